"""``stiffmap.parallel``: the same results wherever tasks run, and bad cluster addresses refused in one line.

The Dask runs of whole campaigns (same database as a local run, a killed client, a killed
worker) are in tests/test_campaign_run.py, on the quick demo.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stiffmap import parallel
from stiffmap.errors import InputError
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
