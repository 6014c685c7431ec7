"""``stiffmap.parallel``: the same results wherever tasks run, and bad cluster addresses refused in one line.

The Dask runs of whole campaigns (same database as a local run, a killed client, a killed
worker) are in tests/test_campaign_run.py, on the quick demo.
"""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import fake_servers
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stiffmap import parallel
from stiffmap.errors import InputError
from stiffmap.geometry import invert_transform, matrix_from_rotvec
from stiffmap.parallel import Backend, map_unordered


def _square_plus(ctx: dict, x: int) -> tuple[int, int]:
    if x < 0:
        raise ValueError(f"negative {x}")
    return x * x + ctx["offset"], os.getpid()


def _with_bytes(x: int) -> int:
    return x + 1  # what `prepare` hands the task instead of the item


def test_every_backend_gives_every_result_once():
    items = list(range(12))
    want = {x: (x + 1) ** 2 + 5 for x in items}  # prepared: x -> x + 1
    seen = {}
    for backend, window in ((Backend(1), None), (Backend(2), 3)):
        got = dict(
            (x, r)
            for x, r in map_unordered(
                _square_plus, {"offset": 5}, items, backend, prepare=_with_bytes, window=window
            )
        )
        assert {x: r[0] for x, r in got.items()} == want
        seen[backend.workers] = {r[1] for r in got.values()}
    assert seen[1] == {os.getpid()}
    assert os.getpid() not in seen[2]  # the pool's processes did the work


def test_a_task_error_reaches_the_caller():
    with pytest.raises(ValueError, match="negative -3"):
        list(map_unordered(_square_plus, {"offset": 0}, [1, -3, 2], Backend(2)))


def _inverses(ctx: dict, item: dict) -> dict:
    arrays = [*ctx.values(), *item.values()]
    return {
        "aligned": all(a.flags.aligned for a in arrays),
        "inverses": [invert_transform(a) for a in arrays if a.dtype == np.float64],
    }


def _transforms(rng, n: int) -> dict:
    """``n`` rigid transforms (mm), each after a byte array of odd length: serialised as
    out-of-band buffers in one message, some would start off their 8-byte alignment."""
    out = {}
    for k in range(n):
        out[f"pad{k}"] = np.zeros(2 * k + 1, np.uint8)
        T = np.eye(4)
        T[:3, :3] = matrix_from_rotvec(rng.normal(0.0, 0.5, 3))
        T[:3, 3] = rng.uniform(-1500.0, 1500.0, 3)
        out[f"T{k}"] = T
    return out


def test_a_dask_task_sees_the_arrays_a_pool_task_sees():
    """On a Dask cluster, a task's context, item and result are aligned arrays, as in a pool:
    NumPy's product with an unaligned operand skips BLAS and its sums differ in the last bit
    (a simulated campaign's truth differed by 1 ulp when rendered on Dask)."""
    pytest.importorskip("distributed")
    rng = np.random.default_rng(7)
    ctx = _transforms(rng, 8)
    items = [_transforms(rng, 3) for _ in range(4)]
    here = {id(it): _inverses(ctx, it) for it in items}
    for item, got in map_unordered(_inverses, ctx, items, Backend(2, dask="local")):
        assert got["aligned"]
        assert all(a.flags.aligned for a in got["inverses"])
        for a, b in zip(got["inverses"], here[id(item)]["inverses"], strict=True):
            assert a.tobytes() == b.tobytes()


@pytest.mark.parametrize(
    "address, said",
    [
        ("foo", "not a scheduler address"),
        ("", "not a scheduler address"),
        ("http://127.0.0.1:80", "scheme 'http'"),
        ("tcp://127.0.0.1:9", "cannot reach the Dask scheduler"),
        ("tcp://no-such-host.invalid:8786", "cannot reach the Dask scheduler"),
    ],
)
def test_bad_scheduler_addresses_are_named(address, said, monkeypatch):
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 0.5)
    with pytest.raises(InputError) as e:
        parallel.Cluster(address)
    msg = str(e.value)
    assert said in msg and "\n" not in msg
    assert msg.startswith(f"--dask {address}") or msg.startswith(f"--dask {address!r}")


_label = st.text(alphabet="abcxyz-_:/.%@[]", min_size=0, max_size=12)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    address=st.one_of(
        st.text(max_size=30),
        st.builds(
            lambda s, h, p: f"{s}://{h}:{p}",
            st.sampled_from(["tcp", "tls", "udp", "inproc", ""]),
            _label,
            st.integers(-5, 1023),
        ),
    )
)
def test_any_scheduler_address_is_an_input_error_or_connects(address, monkeypatch):
    """Malformed --dask values: always an InputError (never a traceback, never a hang). Ports
    below 1024 on this machine: no Dask scheduler listens there."""
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 0.5)
    if address == "local":
        return
    with pytest.raises(InputError):
        parallel.Cluster(address)


@pytest.mark.parametrize("kind", fake_servers.KINDS)
def test_a_server_that_is_not_a_dask_scheduler_is_named_in_one_line(kind, monkeypatch):
    """Programs found at an address taken for a scheduler's (a web server, SSH, one that hangs up,
    binary bytes read as a frame length of exbibytes): one line naming the address, no MemoryError."""
    pytest.importorskip("distributed")
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 0.5)
    address = fake_servers.server(kind)
    level = logging.getLogger("distributed.client").level
    t0 = time.perf_counter()
    with pytest.raises(InputError) as e:
        parallel.Cluster(address)
    assert time.perf_counter() - t0 < 5.0  # the 0.5 s time limit, and Dask's own of the same
    msg = str(e.value)
    assert msg.startswith(f"--dask {address}: what answers there is not a Dask scheduler (")
    assert "\n" not in msg
    assert logging.getLogger("distributed.client").level == level  # left as it was


def _slow_square(ctx, x: int) -> int:
    time.sleep(ctx)
    return x * x


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.long
def test_a_scheduler_that_dies_during_the_work_is_an_input_error_not_a_hang(tmp_path):
    """The scheduler stopped while tasks run: Dask's client tries to reconnect, gives up and
    closes; its futures never finish. The caller gets one line naming the address (about 20 s:
    Dask's reconnection time), with the results received before it."""
    pytest.importorskip("distributed")
    dask = Path(sys.executable).parent / "dask"
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    # Both read this module's task function from the task graph.
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parent)}
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    sched = subprocess.Popen([dask, "scheduler", "--port", str(port), "--no-dashboard"], **quiet)
    worker = None
    try:
        for _ in range(100):
            try:
                socket.create_connection(("127.0.0.1", port), 1).close()
                break
            except OSError:
                time.sleep(0.2)
        worker = subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--no-dashboard"], **quiet)
        got = []
        t0 = time.perf_counter()
        with pytest.raises(InputError) as e:
            for x, r in map_unordered(_slow_square, 0.3, range(200), Backend(dask=address)):
                got.append((x, r))
                if len(got) == 3:
                    sched.kill()
        assert time.perf_counter() - t0 < 120
        assert str(e.value).startswith(f"--dask {address}: the connection to the Dask scheduler failed")
        assert len(got) >= 3 and all(r == x * x for x, r in got)
    finally:
        for p in (worker, sched):
            if p is not None:
                p.kill()
                p.wait()


def test_a_host_name_too_long_for_dns_is_named(monkeypatch):
    """A 300-letter host name is refused by the IDNA codec (UnicodeError, not an OSError)."""
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 0.5)
    address = "tcp://" + "a" * 300 + ":8786"
    with pytest.raises(InputError, match="cannot reach the Dask scheduler") as e:
        parallel.Cluster(address)
    assert str(e.value).startswith(f"--dask {address}: ")
