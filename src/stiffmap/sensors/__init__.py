"""Sensor measurement: displacement-sensor and load recordings to load-displacement curves.

The sensor path of stiffmap (see ``docs/sensors.md``)::

    file (CSV / TDMS / MAT) --read_recording--> Recording (volts, load channel, time)
        --analyse_recording(config)--> SensorResult (plateaus, fit, stiffness, static error)

    [(point, direction, file), ...] --static_errors_from_files--> StaticErrorSet
        (per-point static errors for maps and model fits)

    recordings + index --analyse_batch--> SensorBatch (what ``stiffmap sensor`` prints;
    its option texts are read by ``stiffmap.cli.sensor_options``)

Units inside are N and mm; volts, µm, kgf only at the boundary (``scale_um_per_v``,
``load_kgf``, ``static_error_um`` in JSON).
"""

from .analysis import REFERENCE_LOAD_N, Plateau, SensorConfig, SensorResult, analyse_recording
from .batch import (
    MeasurementEntry,
    SensorBatch,
    StaticErrorSet,
    analyse_batch,
    analyse_files,
    read_measurement_index,
    static_errors_from_files,
)
from .fit import Hysteresis, LinearFit, fit_load_displacement
from .io import read_recording, write_recording
from .plateaus import PlateauDetection, detect_plateaus
from .recording import ChannelMap, Recording, parse_channel_map

__all__ = [
    "REFERENCE_LOAD_N",
    "ChannelMap",
    "Hysteresis",
    "LinearFit",
    "MeasurementEntry",
    "Plateau",
    "PlateauDetection",
    "Recording",
    "SensorBatch",
    "SensorConfig",
    "SensorResult",
    "StaticErrorSet",
    "analyse_batch",
    "analyse_files",
    "analyse_recording",
    "detect_plateaus",
    "fit_load_displacement",
    "parse_channel_map",
    "read_measurement_index",
    "read_recording",
    "static_errors_from_files",
    "write_recording",
]
