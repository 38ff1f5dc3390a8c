"""Recorded IMU logs (MCAP, profile ``ros2``): the public names of both MCAP layers, in one place for users.

The code lives in :mod:`gyroemu.pipelines.formats.mcap_log` (gyroemu's logs: recordings, devices, metadata,
:func:`write_mcap`, :func:`read_mcap`, :class:`McapLogWriter`, :func:`truth_series`) and
:mod:`gyroemu.pipelines.formats.mcap_records` (MCAP records: the bulk :class:`McapFileWriter`, the scanner and
:func:`iter_mcap_batches`); the channel vocabulary (:class:`ImuSeries`, :data:`BODY_FRAME`) in
:mod:`gyroemu.pipelines.formats.channels`. This module only re-exports their names, so that
``from gyroemu.pipelines.mcap_io import read_mcap`` keeps working; gyroemu's own modules import from
the modules above.
"""

from __future__ import annotations

from gyroemu.pipelines.formats.channels import BODY_FRAME, ImuSeries
from gyroemu.pipelines.formats.mcap_log import (
    DeviceLog,
    LogWarning,
    McapLog,
    McapLogWriter,
    Recording,
    read_mcap,
    truth_series,
    write_mcap,
)
from gyroemu.pipelines.formats.mcap_records import (
    OFFERED_QOS_PROFILES,
    ChannelInfo,
    LogError,
    McapFileWriter,
    McapMessage,
    iter_mcap_batches,
    mcap_channel_info,
)

__all__ = [
    "LogError",
    "McapMessage",
    "iter_mcap_batches",
    "ChannelInfo",
    "mcap_channel_info",
    "LogWarning",
    "ImuSeries",
    "Recording",
    "DeviceLog",
    "McapLog",
    "McapLogWriter",
    "McapFileWriter",
    "write_mcap",
    "read_mcap",
    "truth_series",
    "BODY_FRAME",
    "OFFERED_QOS_PROFILES",
]
