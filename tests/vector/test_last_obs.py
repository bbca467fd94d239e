"""LastObs: each worker's latest observations, cut from one array only when asked."""

import numpy as np

from chronogym.vector.last_obs import LastObs


def test_parts_before_any_reset_are_none():
    last = LastObs(3)
    assert [last.never_reset(w) for w in range(3)] == [True, True, True]
    last[1] = np.zeros((2, 4))
    assert [last.never_reset(w) for w in range(3)] == [True, False, True]
    assert len(last) == 3


def test_set_all_gives_each_worker_its_rows():
    whole = np.arange(12.0).reshape(6, 2)
    last = LastObs(3)
    last.set_all(whole, [(0, 1), (1, 4), (4, 6)])
    assert not any(last.never_reset(w) for w in range(3))
    assert len(last) == 3
    np.testing.assert_array_equal(last[1], whole[1:4])
    np.testing.assert_array_equal(np.concatenate(list(last)), whole)


def test_one_part_replaced_after_set_all_keeps_the_others():
    whole = np.arange(8.0).reshape(4, 2)
    last = LastObs(2)
    last.set_all(whole, [(0, 2), (2, 4)])
    last[0] = np.full((2, 2), -1.0)
    np.testing.assert_array_equal(last[0], np.full((2, 2), -1.0))
    np.testing.assert_array_equal(last[1], whole[2:4])
    last.set_all(whole * 2, [(0, 2), (2, 4)])  # the next step replaces every part again
    np.testing.assert_array_equal(last[0], whole[:2] * 2)
