"""The options of ``stiffmap sensor``, as texts, turned into a channel map and a ``SensorConfig``.

``stiffmap sensor`` takes the table of applied loads as ``0,50,40,30,20,10,0``
(kgf or N), plateaus picked by hand as ``0.5-4.2,6-9.5`` (s), the channel map
as ``displacement=COL,load=COL,...`` and each :class:`~stiffmap.sensors.analysis.SensorConfig`
setting on its own. :func:`config_from_options` reads them all, in that order; the library's
:class:`~stiffmap.errors.FieldError` (a ``SensorConfig`` field, ``channel_map``) is worded as
the option that sets it (:func:`sensor_option_names`), never by rewriting its text.
"""

from __future__ import annotations

from ..errors import FieldError, InputError
from ..sensors.analysis import SensorConfig
from ..sensors.recording import ChannelMap, parse_channel_map

__all__ = ["config_from_options", "parse_loads", "parse_step_times", "OPTION_OF", "sensor_option_names"]

#: SensorConfig fields (and the channel map) and the options that set them.
OPTION_OF = {
    "scale_um_per_v": "--scale-um-per-v",
    "range_v": "--range-v",
    "axis_sign": "--axis-sign",
    "load_n_per_v": "--load-n-per-v",
    "reference_load_n": "--reference-load-n",
    "step_times_s": "--step-times",
    "min_plateau_s": "--min-plateau-s",
    "window_s": "--window-s",
    "threshold_sigma": "--threshold-sigma",
    "load_unit": "--load-unit",
    "g": "--g",
    "exclude_bad_samples": "--exclude-bad-samples",
    "channel_map": "--channel-map",
}


def sensor_option_names(steps_n: bool = False) -> dict[str, str]:
    """The fields of a sensor analysis as ``stiffmap sensor``'s options (``steps``: the table given)."""
    return {**OPTION_OF, "steps": "--steps-n" if steps_n else "--steps-kgf"}


def parse_loads(text: str, what: str) -> tuple[float, ...]:
    """A table of loads ``0,50,40,...`` (at least two numbers); ``what`` names the option in errors."""
    vals = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        try:
            vals.append(float(part))
        except ValueError:
            raise InputError(f"{what}: {part!r} is not a number") from None
    if len(vals) < 2:
        raise InputError(f"{what}: give at least two loads, e.g. 0,50,40,30,20,10,0")
    return tuple(vals)


def parse_step_times(text: str) -> tuple[tuple[float, float], ...]:
    """Plateaus by hand, ``START-END`` (or ``START:END``) in s, comma-separated."""
    out = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        if ":" in part:
            a, b = part.split(":", 1)
        elif "-" in part[1:]:
            j = part.index("-", 1)
            a, b = part[:j], part[j + 1 :]
        else:
            raise InputError(f"--step-times: {part!r} should look like START-END (s), e.g. 0.5-4.2")
        try:
            out.append((float(a), float(b)))
        except ValueError:
            raise InputError(f"--step-times: {part!r} should look like START-END (s)") from None
    return tuple(out)


def _steps(steps_kgf: str | None, steps_n: str | None):
    """The table of applied loads and its unit (None, "kgf" without either option)."""
    if steps_kgf and steps_n:
        raise InputError("give either --steps-kgf or --steps-n, not both")
    if steps_kgf:
        return parse_loads(steps_kgf, "--steps-kgf"), "kgf"
    if steps_n:
        return parse_loads(steps_n, "--steps-n"), "N"
    return None, "kgf"


def _load_unit(load_unit: str | None, load_n_per_v: float | None) -> str | None:
    """The load channel's unit: "V" with a load-cell scale (another unit given is an error)."""
    if load_n_per_v is None:
        return load_unit
    if load_unit is not None and load_unit != "V":
        raise InputError(
            f"--load-n-per-v is the scale of a load channel in volts, but --load-unit is "
            f"{load_unit}; leave one out"
        )
    return "V"  # a load-cell scale says the load channel is in volts


def config_from_options(
    channel_map: str | None,
    *,
    steps_kgf: str | None,
    steps_n: str | None,
    step_times: str | None,
    load_unit: str | None,
    load_n_per_v: float | None,
    scale_um_per_v: float,
    range_v: float,
    axis_sign: int,
    g: float,
    reference_load_n: float,
    window_s: float,
    min_plateau_s: float,
    threshold_sigma: float,
    remove_drift: bool,
    exclude_bad_samples: bool,
) -> tuple[ChannelMap, SensorConfig]:
    """The channel map and the configuration that ``stiffmap sensor``'s options describe.

    Parameters
    ----------
    channel_map : str or None
        As :func:`~stiffmap.sensors.recording.parse_channel_map`.
    steps_kgf, steps_n : str or None
        The table of applied loads (:func:`parse_loads`), in kgf or in N; at most one.
    step_times : str or None
        Plateaus by hand (:func:`parse_step_times`).
    load_unit : {"kgf", "N", "V"} or None
        With ``load_n_per_v`` (a load-cell scale, N/V) the load channel is in volts:
        None then means "V", and another unit is an error.
    scale_um_per_v, range_v, axis_sign, g, reference_load_n : float
        The :class:`SensorConfig` fields of the same names.
    window_s, min_plateau_s, threshold_sigma : float
        The step detector's settings (SensorConfig fields).
    remove_drift, exclude_bad_samples : bool
        SensorConfig fields (``remove_drift`` is the opposite of ``--no-drift-removal``).

    Raises
    ------
    InputError
        Naming the option that is wrong (a SensorConfig field is worded as its option,
        :func:`sensor_option_names`).
    """
    steps, unit = _steps(steps_kgf, steps_n)
    names = sensor_option_names(steps_n=bool(steps_n) and not steps_kgf)
    try:
        cmap = parse_channel_map(channel_map)
    except FieldError as e:
        raise e.worded(names) from None
    load_unit = _load_unit(load_unit, load_n_per_v)
    try:
        cfg = SensorConfig(
            scale_um_per_v=scale_um_per_v,
            range_v=range_v,
            axis_sign=axis_sign,
            load_unit=load_unit,
            load_n_per_v=load_n_per_v,
            steps=steps,
            steps_unit=unit,
            g=g,
            reference_load_n=reference_load_n,
            step_times_s=parse_step_times(step_times) if step_times else None,
            window_s=window_s,
            min_plateau_s=min_plateau_s,
            threshold_sigma=threshold_sigma,
            remove_drift=remove_drift,
            exclude_bad_samples=exclude_bad_samples,
        )
    except FieldError as e:
        raise e.worded(names) from None
    except ValueError as e:  # a value SensorConfig cannot take that is no one field's
        raise InputError(str(e)) from None
    return cmap, cfg
