"""Vector envs: RayVectorEnv (Ray actors) and SerialVectorEnv (in process), same semantics.

``make_vec`` builds either of them (or Gymnasium's own); the errors of asynchronous
stepping are ``EnvsInFlightError`` and ``RecvTimeoutError``.

Life of a step -- ``RayVectorEnv.step(actions)`` with Box spaces and the default socket
transport, hop by hop (file: function):

1. ``worker_vector_env.py``: ``WorkerVectorEnv.step`` (RayVectorEnv and SerialVectorEnv
   inherit it) -> ``_step_args`` checks the actions (``actions.py``:
   ``prepare_box_action``) and cuts them into one byte slice per worker.
2. ``worker_vector_env.py``: ``_call_all`` -> ``Backend.submit`` for every worker
   (``backend.py`` defines the protocol). ``socket_transport.py``:
   ``SocketBackend.submit`` writes a request (``wire_format.py``: ``REQUEST``) to the
   worker's socket, or, for a worker on another node, queues it for that node's relay
   (``relay.py``: ``Relays.submit``; ``Relays.flush`` sends one ``NodeRelay.step`` call
   per node, which writes the requests to its workers' sockets there). Other backends:
   ``actor_transport.py``: ``ActorBackend.submit`` (a Ray actor call); ``serial.py``:
   ``LocalBackend.submit`` (runs the call at once);
   ``driver_worker.py``: ``DriverWorkerBackend.submit`` (the driver's own worker).
3. In the worker, ``socket_transport.py``: ``_serve_conn`` reads the request
   (``wire_format.py``: ``fill``) and calls ``group.py``: ``EnvGroup.step_packed`` ->
   ``EnvGroup.step`` (Gymnasium's autoreset; an env that raised answers with an
   ``EnvRaised``, ``env_errors.py``, or is rebuilt with ``env_errors="restart"``), which
   returns a ``StepAnswer`` (``backend.py``); ``wire_format.py``: ``encode_answer``
   turns it into the answer's bytes (infos as columns: ``infos.py``: ``to_columns``).
4. Back in the driver, ``Backend.gather`` -> ``socket_transport.py``:
   ``SocketBackend._read`` (or ``_resolve_relayed``: the relay's answer for that worker)
   -> ``wire_format.py``: ``decode_answer``: one ``Outcome`` (``backend.py``) per
   worker, holding its ``StepAnswer`` or its error.
5. ``worker_vector_env.py``: ``_step_parts`` unpacks each answer (``_step_result``),
   logs the envs rebuilt inside workers, replaces a lost worker (``_replace_worker`` ->
   ``Backend.replace``; ``worker_death.py`` names the signal it died of), reporting its
   envs truncated, and raises an env's own exception once every answer is read
   (``env_errors.py``: ``driver_error``).
6. ``worker_vector_env.py``: ``_join_results`` joins the workers' parts
   (``batching.py``: ``join_obs``; ``infos.py``: ``join_infos``).

With every worker on the driver's node (the usual case), the barrier ``step`` skips hops
2-4's one message per worker: ``worker_vector_env.py``: ``_shared_step`` ->
``socket_transport.py``: ``SocketBackend.shared_step`` -> ``shared_step.py``:
``SharedStep.step`` copies the actions into a memory block shared with the workers and
wakes them all with one byte on a pipe; each worker's ``_serve_conn`` calls
``SharedServer.serve`` (the same ``EnvGroup.step_packed``), which writes its rows and counts
its answer; the last one wakes the driver, which copies every row out at once. Infos that
are the same numeric scalars in every env are rows too (``info_rows.py``: ``RowWriter``
in the worker, ``join_rows`` in the driver). A worker with other infos, restarts or an
error writes its whole answer (``encode_answer``) beside its rows, and hops 5-6 take it
from there. With workers on other nodes too, ``shared_step``
goes to ``SocketBackend._spread_step`` -> ``spread_step.py``: ``SpreadStep.step``, which
sends each other node's relay its rows as one frame over that relay's TCP line
(``relay_channel.py``: ``DriverLine.send``; ``RelayLine`` calls ``NodeRelay.shared_step``,
which runs the same ``SharedStep.step`` over a block of its own node; with
``relay_tcp=False``, a Ray call of it), steps the driver's node's workers through the
driver's block meanwhile, and copies each node's returned rows (``DriverLine.receive``)
into the batch. ``shared_memory=False`` keeps the messages.

``send`` / ``recv`` (and ``step_async`` / ``step_wait``, ``async_reset``) take the same
hops, except that the calls wait in ``in_flight.py``: ``InFlight.submit`` /
``InFlight.collect`` (``Backend.wait``, then ``Backend.gather``) until enough envs
have answered (at most ``max_envs``: the rest stay answered for the next ``recv``), and
``_pending_result`` reads each answer. The docs' "How it works" page
(docs/how-it-works.md) tells the whole story: processes, what travels, where faults are caught.

:mod:`chronogym.optim.parallel` runs its Optuna trials on the same machinery: an
``ActorBackend`` (or ``LocalBackend``) of ``TrialWorker``s and an ``InFlight``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from chronogym._lazy import lazy_exports

_EXPORTS = {
    "RayVectorEnv": "chronogym.vector.ray_vector_env",
    "SerialVectorEnv": "chronogym.vector.serial",
    "make_vec": "chronogym.vector.factory",
    "EnvsInFlightError": "chronogym.errors",
    "RecvTimeoutError": "chronogym.errors",
}

__all__ = ["EnvsInFlightError", "RayVectorEnv", "RecvTimeoutError", "SerialVectorEnv", "make_vec"]

if TYPE_CHECKING:
    from chronogym.errors import EnvsInFlightError, RecvTimeoutError
    from chronogym.vector.factory import make_vec
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
