"""Where heavy work runs: in this process, in a pool of processes, or on a Dask cluster.

One function, :func:`map_unordered`, runs ``fn(ctx, item)`` for every item and yields
``(item, result)`` as each finishes. ``ctx`` is what every task shares (a campaign's
camera and boards, a simulation's scene): it is sent once per worker, not once per
task. The caller stays the only writer of results (the campaign database, the
simulation's ``truth.json``): workers compute and return.

Backends (:class:`Backend`):

- ``workers == 1``, no ``dask``: every task in this process, in order;
- ``workers > 1``: a :class:`concurrent.futures.ProcessPoolExecutor`;
- ``dask``: a ``dask.distributed`` cluster, ``"local"`` for a
  :class:`distributed.LocalCluster` of ``workers`` single-threaded processes on this
  machine, else the address of a running scheduler (``tcp://host:8786``). A task whose
  worker dies is run again on another worker (Dask's own retry; after
  ``distributed.scheduler.allowed-failures`` deaths it is given up and yields a
  :class:`Lost`). ``dask.distributed`` is an optional extra
  (``pip install 'stiffmap[dask]'``), imported only when a cluster is asked for.

Objects on a cluster travel as pickles of their own (:func:`_pack`: arrays inside, as a
process pool sends them), not through Dask's serialisation, which rebuilds small arrays
as views into a received message at any byte offset: a float64 array 4 bytes off its
alignment makes NumPy's matrix product take another loop than BLAS's, whose sums differ
in the last bit (a simulated campaign's truth rendered on Dask differed from the pool's).
A task's context, its item and its result are thus the same arrays, bit for bit and
aligned, wherever it runs.

Files on a cluster: :meth:`Cluster.sees` tells whether every worker reads the same
file at the same path (shared storage); when one does not, the caller sends the
bytes with the task instead (``stiffmap run``) or has them sent back
(``stiffmap simulate``).
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import gc
import hashlib
import logging
import os
import pickle
import signal
import socket
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, CancelledError, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from .errors import InputError

__all__ = ["Backend", "Cluster", "Lost", "connected", "map_unordered", "file_digest", "local_workers"]

#: How long to wait for a scheduler to answer, and for it to have a worker (seconds).
CONNECT_TIMEOUT_S = 15.0
WORKERS_TIMEOUT_S = 60.0


def local_workers() -> int:
    """The CPUs this process may use (the default number of worker processes)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class Backend:
    """Where to run: ``workers`` processes here, or the Dask cluster ``dask`` ("local" or an address).

    ``cluster`` is the open connection (:func:`connected`): several calls of
    :func:`map_unordered` then share one cluster instead of starting one each.
    """

    workers: int = 1
    dask: str | None = None
    #: Start method of a local process pool (None: the platform's default).
    start_method: str | None = None
    cluster: Cluster | None = field(default=None, compare=False, repr=False)

    def describe(self) -> str:
        """``"2 processes"``, ``"Dask cluster at tcp://..."``, ``"a local Dask cluster of 2 workers"``."""
        if self.dask == "local":
            return f"a local Dask cluster of {self.workers} worker(s)"
        if self.dask:
            return f"the Dask cluster at {self.dask}"
        return f"{self.workers} process(es)"


@contextlib.contextmanager
def connected(backend: Backend) -> Iterator[Backend]:
    """``backend`` with its cluster connected (started, for ``"local"``) for the block, then closed.

    A backend without ``dask``, or already connected, is given back as it is.

    Raises
    ------
    InputError
        dask.distributed not installed, the scheduler cannot be reached or has no
        worker, a local cluster could not start.
    """
    if not backend.dask or backend.cluster is not None:
        yield backend
        return
    with Cluster(backend.dask, backend.workers) as c:
        yield replace(backend, cluster=c)


@dataclass(frozen=True)
class Lost:
    """A task given up by the cluster (its workers kept dying): why, in one line."""

    reason: str


def file_digest(path: str | os.PathLike, limit: int = 1 << 16) -> tuple[int, str]:
    """(size, SHA-256 of the first ``limit`` bytes) of a file: enough to tell two copies apart."""
    p = Path(path)
    with p.open("rb") as f:
        head = f.read(limit)
    return p.stat().st_size, hashlib.sha256(head).hexdigest()


def _same_file(path: str, digest: tuple[int, str]) -> bool:
    try:
        return file_digest(path) == tuple(digest)
    except OSError:
        return False


class Cluster:
    """A connection to a Dask cluster (started on this machine for ``"local"``); a context manager."""

    def __init__(self, address: str, workers: int = 1):
        try:
            import distributed  # optional extra: only a cluster run needs it
        except ImportError:
            raise InputError(
                "--dask needs dask.distributed, which is not installed: pip install 'stiffmap[dask]'"
            ) from None
        self.address = address
        self._cluster = None
        self._dist = distributed
        self.client = None
        #: What happened to the cluster during the work (workers that left), one line each.
        self.events: list[str] = []
        # The client's own log lines ("Failed to reconnect to scheduler...") would come beside
        # stiffmap's one-line message of the same event: quiet while this cluster is open.
        self._log = logging.getLogger("distributed.client")
        self._log_level = self._log.level
        self._log.setLevel(logging.CRITICAL)
        try:
            self._connect(workers)
        except BaseException:
            self.close()
            raise

    def _connect(self, workers: int) -> None:
        """Start the local cluster or check the scheduler, connect the client, wait for a worker."""
        distributed, address = self._dist, self.address
        if address == "local":
            try:
                with _ctrl_c_ignored():  # its processes inherit it: Ctrl-C is this process's to handle
                    self._cluster = distributed.LocalCluster(
                        n_workers=max(1, int(workers)),
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=":0",  # a free port, none taken from another cluster
                        silence_logs=logging.ERROR,
                    )
            except (OSError, RuntimeError, TimeoutError) as e:
                raise InputError(
                    f"--dask local: could not start a local Dask cluster ({_one_line(e)})"
                ) from None
            target: Any = self._cluster
        else:
            _check_reachable(distributed, address)
            target = address
        failure = None
        try:
            self.client = distributed.Client(target, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except Exception as e:  # noqa: BLE001 - whatever the client meets there, said in one line
            failure = _one_line(e)
        if failure is not None:
            with _quiet_unraisable():  # the half-made client complains as it is collected
                gc.collect()
            raise InputError(f"--dask {address}: no Dask scheduler answers there ({failure}); " + _START_HINT)
        try:
            self.client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
        except TimeoutError as e:
            raise InputError(
                f"--dask {address}: the scheduler has no worker after {WORKERS_TIMEOUT_S:.0f} s "
                f"({_one_line(e)}); start workers with 'dask worker {address}'"
            ) from None
        except Exception as e:  # noqa: BLE001 - the scheduler went away, or was not one after all
            raise self.lost(e) from None
        with self.talking():
            self._known = set(self.client.scheduler_info().get("workers", {}))

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.client.close()
        self._close_cluster()
        self._log.setLevel(self._log_level)

    def _close_cluster(self) -> None:
        if self._cluster is not None:
            with contextlib.suppress(Exception):
                self._cluster.close()
            self._cluster = None

    def lost(self, e: BaseException) -> InputError:
        """The error of a connection to the scheduler that failed after it was made."""
        return InputError(
            f"--dask {self.address}: the connection to the Dask scheduler failed ({_one_line(e)}); "
            "is it still running? The results received before are kept"
        )

    @contextlib.contextmanager
    def talking(self) -> Iterator[None]:
        """A block talking to the scheduler: a lost connection (or a server that stops speaking
        Dask) is an InputError naming the address, not a traceback."""
        comm_closed = getattr(getattr(self._dist, "comm", None), "CommClosedError", OSError)
        closed_client = getattr(getattr(self._dist, "client", None), "ClosedClientError", OSError)
        try:
            yield
        except (OSError, TimeoutError, comm_closed, closed_client) as e:
            raise self.lost(e) from None

    def note_departures(self) -> list[str]:
        """Workers that left the cluster since the last call, each said once in :attr:`events`."""
        with self.talking():
            now = set(self.client.scheduler_info().get("workers", {}))
        gone = sorted(self._known - now)
        self._known |= now
        self._known -= set(gone)
        for w in gone:
            self.events.append(
                f"the Dask worker {w} left the cluster during the run (it died or was stopped); "
                "Dask ran its tasks again on the other workers"
            )
        return gone

    @property
    def n_workers(self) -> int:
        """Threads over all workers (tasks that can run at once)."""
        with self.talking():
            workers = self.client.scheduler_info().get("workers", {})
        return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))

    def sees(self, path: str | os.PathLike) -> bool:
        """Whether every worker reads the same file at ``path`` (same size, same first 64 KiB)."""
        digest = file_digest(path)
        with self.talking():
            answers = self.client.run(_same_file, str(Path(path).resolve()), digest)
        return bool(answers) and all(answers.values())

    def share(self, ctx: Any) -> Any:
        """``ctx`` sent once to every worker; pass the result to tasks in its place."""
        with self.talking():
            return self.client.scatter(ctx, broadcast=True, hash=False)

    def lost_reason(self, exc: BaseException) -> str | None:
        """One line when ``exc`` is the cluster giving a task up (its workers died), else None."""
        killed = getattr(self._dist, "KilledWorker", None) or self._dist.scheduler.KilledWorker
        if isinstance(exc, killed):
            return f"the Dask workers running it died repeatedly ({_one_line(exc)})"
        return None


_START_HINT = (
    "start one ('dask scheduler', then 'dask worker ADDRESS' on each machine) and give its "
    "address as tcp://HOST:PORT, or use --dask local"
)


def _check_reachable(distributed, address: str) -> None:
    """InputError unless ``address`` is a scheduler address whose host and port accept a connection."""
    try:
        scheme, location = distributed.comm.parse_address(address)
        host, port = distributed.comm.parse_host_port(location)
    except (ValueError, TypeError) as e:
        raise InputError(
            f"--dask {address!r}: not a scheduler address ({_one_line(e)}); expected 'local' or "
            "tcp://HOST:PORT (e.g. tcp://192.168.1.20:8786)"
        ) from None
    if scheme not in ("tcp", "tls"):
        raise InputError(f"--dask {address}: scheme {scheme!r}; expected tcp://HOST:PORT or tls://HOST:PORT")
    try:
        greeting = _greeting(host, int(port)) if scheme == "tcp" else None
    except (OSError, UnicodeError, ValueError, OverflowError) as e:  # refused, no such host, not a name
        raise InputError(
            f"--dask {address}: cannot reach the Dask scheduler ({_one_line(e)}); " + _START_HINT
        ) from None
    if greeting is not None:
        raise _not_dask(address, greeting)

    async def identity() -> Any:
        comm = await distributed.comm.connect(address, timeout=CONNECT_TIMEOUT_S)
        try:
            await comm.write({"op": "identity"})
            return await comm.read()
        finally:
            await comm.close()

    # Something answers there; a Dask client would wait for ever on a server that is not Dask's.
    try:
        answer = asyncio.run(asyncio.wait_for(identity(), CONNECT_TIMEOUT_S))
    except Exception as e:  # noqa: BLE001 - whatever a server that is not Dask's makes Dask raise
        answer = e
    if isinstance(answer, dict) and answer.get("type") == "Scheduler":
        return
    if isinstance(answer, BaseException):
        what = (
            f"no Dask answer in {CONNECT_TIMEOUT_S:g} s"
            if isinstance(answer, TimeoutError)
            else _one_line(answer)
        )
    else:
        what = f"it says it is a {answer.get('type', '?')}" if isinstance(answer, dict) else "no identity"
    raise _not_dask(address, what)


def _not_dask(address: str, what: str) -> InputError:
    what = f"--dask {address}: what answers there is not a Dask scheduler ({what}); "
    return InputError(what + _START_HINT)


#: The longest first message of a Dask server (its handshake: a few dozen bytes), bytes.
MAX_GREETING_BYTES = 1 << 20


def _greeting(host: str, port: int) -> str | None:
    """None when the server at (host, port) opens as a Dask server does, else what it did instead.

    A Dask server speaks first: on accepting a connection it sends its handshake, one frame
    whose 8-byte length (little-endian) is a few dozen bytes. Read here from a bare socket,
    before Dask's client sees the server: Dask would take any 8 bytes for a frame's length,
    and the first bytes of an HTTP or SSH server's answer make it allocate exbibytes.

    Raises
    ------
    OSError
        Nothing accepts connections there (refused, unknown host, unreachable).
    """
    with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S) as s:
        head, ended = b"", "closed the connection"
        try:
            while len(head) < 8:
                chunk = s.recv(8 - len(head))
                if not chunk:
                    break
                head += chunk
        except TimeoutError:
            ended = f"said nothing more in {CONNECT_TIMEOUT_S:g} s"
            if not head:
                return (
                    f"it says nothing in {CONNECT_TIMEOUT_S:g} s, where a Dask scheduler greets at once: "
                    "a web server waiting for a request?"
                )
        except OSError as e:
            return f"it dropped the connection: {_one_line(e)}"
    if len(head) < 8:
        return f"it {ended}" + (f" after {len(head)} byte(s)" if head else " without a word")
    n = int.from_bytes(head, "little")
    if 0 < n <= MAX_GREETING_BYTES:
        return None
    text = head.decode("ascii", errors="replace")
    said = f"it begins with {text!r}" if text.isprintable() else f"it begins with the bytes {head.hex(' ')}"
    return f"{said}, not a Dask handshake"


@contextlib.contextmanager
def _ctrl_c_ignored() -> Iterator[None]:
    """SIGINT ignored for the block (in the main thread; elsewhere nothing changes).

    Processes started in the block inherit the ignored signal (it survives ``exec``): a Ctrl-C
    in the terminal then stops this process, which closes them, instead of each printing its
    own traceback. A Ctrl-C during the block itself is lost.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


@contextlib.contextmanager
def _quiet_unraisable() -> Iterator[None]:
    """Drop the 'Exception ignored in Client.__del__' reports of a client that never connected."""
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None
    try:
        yield
    finally:
        sys.unraisablehook = hook


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return text[0] if text else type(e).__name__


# ------------------------------------------------------------------ running tasks

_CTX: dict[str, Any] = {}


def _init_process(init: Callable[[Any], None] | None, ctx: Any) -> None:
    _CTX["ctx"] = ctx
    if init is not None:
        init(ctx)


def _init_pool_process(init: Callable[[Any], None] | None, ctx: Any) -> None:
    """A pool worker's start: Ctrl-C is the parent's to handle (it stops the pool), not each worker's
    (whose tracebacks would fill the terminal)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _init_process(init, ctx)


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a pool now (Ctrl-C): its queued tasks cancelled, its running ones' processes ended.

    Workers only compute (the caller is the only writer of results): nothing is lost that a
    re-run does not redo.
    """
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        with contextlib.suppress(Exception):
            proc.terminate()


def _call_in_process(fn: Callable[[Any, Any], Any], item: Any) -> Any:
    return fn(_CTX["ctx"], item)


def _pack(obj: Any) -> bytes:
    """``obj`` pickled with its arrays' data inside the pickle (no out-of-band buffers).

    Unpickled, every array is a fresh, aligned one: what a process pool's worker receives.
    Dask's own serialisation of the same object may give arrays that are views at any byte
    offset of a message, whose products NumPy computes without BLAS (other last bits).
    """
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def _call_on_worker(
    fn: Callable[[Any, Any], Any], init: Callable[[Any], None] | None, token: str, ctx: bytes, item: bytes
) -> bytes:
    """``fn(ctx, item)`` on a Dask worker, from and to :func:`_pack`'s bytes; the context is
    unpacked (and ``init`` run) once per worker and :func:`map_unordered` call (``token``)."""
    if "malloc" not in _CTX:
        _CTX["malloc"] = _keep_large_buffers()
    current = _CTX.get("cluster")
    if current is None or current[0] != token:
        current = (token, pickle.loads(ctx))
        if init is not None:
            init(current[1])
        _CTX["cluster"] = current
    return _pack(fn(current[1], pickle.loads(item)))


def _keep_large_buffers() -> bool:
    """Let glibc reuse large freed buffers in a Dask worker (True when it could be told).

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes
    glibc's mmap threshold: every image-sized array is then mapped and unmapped afresh,
    and measuring a 5 MP image took twice as long (11.1 s against 5.9 s for 40 images).
    A 64 MiB mmap threshold and a 128 MiB trim threshold bring the time back.
    """
    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc: nothing to tune
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3
    return bool(mallopt(m_mmap_threshold, 1 << 26)) and bool(mallopt(m_trim_threshold, 1 << 27))


def map_unordered(
    fn: Callable[[Any, Any], Any],
    ctx: Any,
    items: Iterable[Any],
    backend: Backend,
    *,
    init: Callable[[Any], None] | None = None,
    prepare: Callable[[Any], Any] | None = None,
    window: int | None = None,
) -> Iterator[tuple[Any, Any]]:
    """Run ``fn(ctx, task)`` for every item; yield ``(item, result)`` as each finishes.

    Parameters
    ----------
    fn : callable
        ``fn(ctx, task)``, a module-level function (it is pickled to the workers).
        Its exceptions propagate to the caller (wrap them in ``fn`` to keep going).
    ctx : object
        Shared by every task; sent once per worker (picklable).
    items : iterable
        The tasks' items, in submission order.
    backend : Backend
        Where; a Dask backend not yet :func:`connected` is connected for this call.
    init : callable, optional
        ``init(ctx)`` once in each process before its first task (e.g. thread settings).
    prepare : callable, optional
        ``prepare(item)`` in this process just before the item is submitted; ``fn``
        receives its result instead of the item (e.g. a task with its files' bytes).
    window : int, optional
        At most this many tasks submitted and not yet yielded (a memory bound with
        ``prepare``); all at once when None.

    Yields
    ------
    (item, result)
        ``result`` is ``fn``'s return, or a :class:`Lost` when a cluster gave the task up.
        Closing the iterator early cancels what is not done.
    """
    items = list(items)
    if not items:
        return
    prep = prepare if prepare is not None else (lambda x: x)
    if backend.dask:
        with connected(backend) as b:
            yield from _on_cluster(b.cluster, fn, ctx, items, init, prep, window)
        return
    if backend.workers <= 1:
        _init_process(init, ctx)
        for item in items:
            yield item, fn(ctx, prep(item))
        return
    mp = get_context(backend.start_method) if backend.start_method else None
    limit = window or len(items)
    with ProcessPoolExecutor(
        max_workers=backend.workers, mp_context=mp, initializer=_init_pool_process, initargs=(init, ctx)
    ) as pool:
        queue = iter(items)
        pending: dict[Any, Any] = {}
        try:
            for item in queue:
                pending[pool.submit(_call_in_process, fn, prep(item))] = item
                if len(pending) >= limit:
                    break
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    item = pending.pop(fut)
                    yield item, fut.result()
                    for nxt in queue:
                        pending[pool.submit(_call_in_process, fn, prep(nxt))] = nxt
                        break
        except KeyboardInterrupt:
            _stop_pool(pool)
            raise
        finally:
            for fut in pending:
                fut.cancel()


#: Submissions of one task before it is given up when the data sent with it is lost with a worker.
MAX_SUBMISSIONS = 3


def _on_cluster(cluster: Cluster, fn, ctx, items, init, prep, window) -> Iterator[tuple[Any, Any]]:
    """:func:`map_unordered` on a Dask cluster.

    A task whose worker dies is run again by Dask itself. Data scattered for a task (its
    files' bytes) lives on one worker and dies with it: such a task is cancelled by Dask,
    and submitted again from here (``prepare`` called again), up to :data:`MAX_SUBMISSIONS`.
    """
    client = cluster.client
    shared = cluster.share(_pack(ctx))
    token = uuid.uuid4().hex
    limit = window or len(items)
    queue = iter(range(len(items)))
    pending: dict[Any, tuple[Any, int]] = {}
    submissions = [0] * len(items)

    def submit(k: int):
        arg = prep(items[k])
        large = _is_large(arg)
        arg = _pack(arg)
        with cluster.talking():
            if large:  # big data goes beside the task graph, not inside it
                [arg] = client.scatter([arg], hash=False)
            fut = client.submit(_call_on_worker, fn, init, token, shared, arg, pure=False)
        pending[fut.key] = (fut, k)
        submissions[k] += 1
        return fut

    first = []
    for k in queue:
        first.append(submit(k))
        if len(pending) >= limit:
            break
    futures = cluster._dist.as_completed(first, loop=client.loop)
    try:
        while pending:
            fut = _next_done(cluster, futures)
            _, k = pending.pop(fut.key)
            try:
                result = pickle.loads(fut.result())
            except CancelledError:  # its sent data died with a worker: send it again
                fut.release()
                if submissions[k] < MAX_SUBMISSIONS:
                    futures.add(submit(k))
                    continue
                result = Lost(f"the data sent with it was lost with {submissions[k]} workers")
            except Exception as e:  # a dead worker's task given up: the run goes on without it
                reason = cluster.lost_reason(e)
                if reason is None:
                    raise
                result = Lost(reason)
            fut.release()
            cluster.note_departures()
            yield items[k], result
            for nxt in queue:
                futures.add(submit(nxt))
                break
    finally:
        for fut, _ in pending.values():
            with contextlib.suppress(Exception):  # a closed client refuses to cancel
                fut.cancel()


#: Seconds between two looks at the client's connection while waiting for a task.
POLL_S = 0.05


def _next_done(cluster: Cluster, futures) -> Any:
    """The next finished future of ``futures`` (an ``as_completed``); an InputError when the
    client has lost its scheduler: Dask's client gives up reconnecting after a while, and the
    futures of a closed client never finish."""
    while not futures.has_ready():
        if cluster.client.status not in ("running", "connecting", "newly-created"):
            raise cluster.lost(ConnectionError(f"the client is {cluster.client.status}"))
        time.sleep(POLL_S)
    return next(futures)


def _is_large(arg: Any, limit: int = 1 << 20) -> bool:
    """Whether a task's argument is big enough to be scattered rather than put in the task (bytes)."""
    if isinstance(arg, bytes | bytearray):
        return len(arg) > limit
    if isinstance(arg, dict):
        return sum(len(v) for v in arg.values() if isinstance(v, bytes | bytearray)) > limit
    if isinstance(arg, tuple):
        return any(_is_large(a, limit) for a in arg)
    return False
