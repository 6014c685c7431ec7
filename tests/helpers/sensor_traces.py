"""Short simulated sensor recordings, quick to analyse, for the sensor tests."""

from __future__ import annotations

from stiffmap.sim.traces import DaqChain, LoadSteps, simulate_trace

#: A short recording's DAQ chain: 500 Hz, the milling study's LDV chain (640 um/V, +-8 V,
#: 16 bit over +-10 V), 1 um noise, slow drift.
FAST_DAQ_CHAIN = DaqChain(sample_rate_hz=500.0, noise_um=1.0)
#: A short recording's load protocol: 2 s plateaus, 0.8 s transitions.
FAST_LOAD_STEPS = LoadSteps(plateau_s=2.0, transition_s=0.8)


def quick_trace(static_error_mm: float = 0.5, seed: int = 0, *, chain=None, protocol=None, **kw):
    """A simulated stepped-load recording (0, 50, 40, 30, 20, 10, 0 kgf) with its truth.

    ``chain`` and ``protocol`` default to :data:`FAST_DAQ_CHAIN` and :data:`FAST_LOAD_STEPS`.
    """
    return simulate_trace(
        static_error_mm=static_error_mm,
        chain=chain or FAST_DAQ_CHAIN,
        protocol=protocol or FAST_LOAD_STEPS,
        seed=seed,
        **kw,
    )
