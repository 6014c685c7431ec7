"""``stiffmap.parallel``: the same results wherever tasks run, and bad cluster addresses refused in one line.

The Dask runs of whole campaigns (same database as a local run, a killed client, a killed
worker) are in tests/test_campaign_run.py, on the quick demo.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
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
