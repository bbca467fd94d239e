"""The relay's TCP line (relay_channel.py) over loopback: token, frames, failures."""

from __future__ import annotations

import contextlib
import socket

import numpy as np
import pytest

from chronogym.vector.relay_channel import (
    TOKEN_BYTES,
    DriverLine,
    RelayLine,
    decode_extras,
    encode_extras,
)

ROWS, ACTION_ROW, OBS_ROW = 3, 8, 5


def echo_step(actions: memoryview):
    """A node's step: obs rows from the action bytes, reward = row sum, one worker's extras."""
    got = np.frombuffer(actions, np.uint8).reshape(ROWS, ACTION_ROW)
    obs = got[:, :OBS_ROW].copy()
    rewards = got.sum(axis=1).astype(np.float64)
    terminations = got[:, 0] > 100
    truncations = np.zeros(ROWS, np.bool_)
    extras = [(7, "answered", bytes(got[0]))] if got[0, 0] == 1 else []
    return obs, rewards, terminations, truncations, extras


@contextlib.contextmanager
def listening(step=echo_step):
    """A relay's line serving ``step``, closed afterwards."""
    relay = RelayLine("127.0.0.1", accept_timeout=10.0)
    relay.serve(ROWS, ACTION_ROW, step)
    try:
        yield relay
    finally:
        relay.close()


def dial(relay: RelayLine, token: bytes | None = None, timeout: float = 10.0):
    return DriverLine.dial(relay.address, token or relay.token, ROWS, OBS_ROW, timeout)


def test_extras_round_trip_bytes_and_reasons():
    extras = [(0, "answered", b"\x00\x01raw"), (12, "lost", "its socket failed: é"),
              (3, "silent", "no answer"), (0, "rows", b"\x05\x00\x00\x00texts\xff")]  # fmt: skip
    assert decode_extras(memoryview(encode_extras(extras))) == extras
    assert decode_extras(memoryview(b"")) == []


def test_a_line_steps_rows_both_ways():
    with listening() as relay:
        line = dial(relay)
        assert line is not None
        for first in (0, 1, 200):
            actions = np.arange(ROWS * ACTION_ROW, dtype=np.uint8).reshape(ROWS, ACTION_ROW)
            actions[0, 0] = first
            line.send(actions, timeout=10.0)
            obs, rewards, terminations, truncations, extras = line.receive()
            np.testing.assert_array_equal(obs, actions[:, :OBS_ROW])
            np.testing.assert_array_equal(rewards, actions.sum(axis=1))
            assert terminations.tolist() == [first > 100, False, False]
            assert not truncations.any()
            assert extras == ([(7, "answered", actions[0].tobytes())] if first == 1 else [])
        line.close()


def test_a_wrong_token_is_refused_and_the_right_one_still_gets_in():
    with listening() as relay:
        assert dial(relay, b"x" * TOKEN_BYTES, timeout=5.0) is None
        line = dial(relay)
        assert line is not None
        line.close()


def test_a_silent_peer_is_dropped_and_the_driver_still_gets_in():
    with listening() as relay:
        silent = socket.create_connection(relay.address, timeout=5.0)  # sends nothing
        line = dial(relay)
        assert line is not None
        assert silent.recv(1) == b""  # dropped after TOKEN_TIMEOUT_S
        silent.close()
        line.close()


def test_the_listener_takes_one_line_only():
    with listening() as relay:
        line = dial(relay)
        assert line is not None
        with pytest.raises(OSError):  # the listener closed once the driver got in
            socket.create_connection(relay.address, timeout=2.0)
        line.close()


def test_a_failing_step_is_reported_and_the_line_goes_on():
    calls = []

    def step(actions):
        calls.append(1)
        if len(calls) == 1:
            raise ValueError("env exploded")
        return echo_step(actions)

    with listening(step) as relay:
        line = dial(relay)
        assert line is not None
        actions = np.zeros((ROWS, ACTION_ROW), np.uint8)
        line.send(actions, timeout=10.0)
        with pytest.raises(RuntimeError, match="ValueError: env exploded"):
            line.receive()
        line.send(actions, timeout=10.0)
        assert line.receive()[1].tolist() == [0.0, 0.0, 0.0]
        line.close()


def test_a_closed_relay_ends_the_line_with_an_error():
    with listening() as relay:
        line = dial(relay)
        assert line is not None
        relay.close()
        with pytest.raises((OSError, EOFError)):
            line.send(np.zeros((ROWS, ACTION_ROW), np.uint8), timeout=5.0)
            line.receive()
        line.close()
