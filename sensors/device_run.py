"""One device measuring one motion from power-up, a block of samples at a time, in bounded memory.

:class:`DeviceRun` is what :meth:`gyroemu.sensors.Device.measure` does, as an iterator: it reads its
truth a window at a time from a :class:`~gyroemu.dynamics.truth_source.TruthSource` and yields the
device's samples in blocks, carrying every state from one block to the next: the gyro mechanism's
(:mod:`gyroemu.sensors.mechanism`), the error terms' (:class:`gyroemu.sensors.errors.SensorErrors`:
noise recurrences, filter, pulse counter), the clock's and the random streams'. Memory is that of two
blocks (one measured while the next is read on a worker thread, :meth:`DeviceRun._blocks_ahead`),
whatever the run's length; a run without end (a source whose ``t_end`` is None) yields blocks until its
consumer stops.

Blocks start at fixed sample counts from power-up (every :attr:`DeviceRun.block_samples`, a property of
the device, not of the run), and every computation is made a block at a time, so a run's samples do
not depend on how it is consumed: :meth:`Device.measure` on a trajectory in memory, a run read a block
at a time from a scenario evaluated window by window, and any grouping of blocks into chunks give the
same bytes. Within a block, the computations are those of the module notes of
:mod:`gyroemu.sensors.imu` (clock, mechanism on its inner grid, error terms, accelerometer,
magnetometer, latencies).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics import Trajectory
from gyroemu.dynamics.jit import njit
from gyroemu.errors import ConfigError

from .accelerometer import mean_specific_force
from .errors import SensorErrors
from .mechanism import GyroTruth
from .samples import ImuSamples
from .sampling import SensorTruth

if TYPE_CHECKING:
    from gyroemu.dynamics.truth_source import TruthSource

    from .imu import Device

__all__ = ["BLOCK_INNER_SAMPLES", "BLOCK_MAX_SAMPLES", "MeasuredBlock", "DeviceRun", "concatenate_samples"]

BLOCK_INNER_SAMPLES = 1 << 18
"""Inner-grid samples of the gyro mechanism per block, at most (bounds memory on fast mechanisms)."""

BLOCK_MAX_SAMPLES = 1 << 14
"""Output samples per block, at most."""


@dataclass(frozen=True)
class _OtherSensors:
    """What the sensors read on the worker thread carry from block to block (:meth:`DeviceRun._read`)."""

    rng_clock: np.random.Generator  # the clock's jitter
    accel_errors: SensorErrors  # the accelerometer's error terms, with their states and generator
    rng_mag: np.random.Generator  # the magnetometer's noise


@dataclass(frozen=True)
class _BlockReading:
    """One block's samples but for the gyro's, and what the gyro reads (:meth:`DeviceRun._read`)."""

    stamps: NDArray[np.float64]  # (n,) sample stamps, device clock, s
    instants: NDArray[np.float64]  # (n + 1,) true interval bounds τ_{k−1} … τ_k, s
    window: Trajectory  # the truth samples read
    truth: SensorTruth  # their interpolants
    temperature: NDArray[np.float64]  # (n,) °C at τ_k
    gyro_truth: GyroTruth  # the gyro mechanism's inner grid
    gyro_force_mean: NDArray[np.float64] | None  # (n, 3) the mean specific force the gyro's g-sensitivity reads
    accel: NDArray[np.float64]  # (n, 3) the accelerometer's samples, m/s²
    mag: NDArray[np.float64]  # (n, 3) the magnetometer's samples, T (NaN without one)


@dataclass(frozen=True)
class MeasuredBlock:
    """One block of a run: the device's samples and the truth window they were measured from.

    Attributes
    ----------
    samples : ImuSamples
        The block's output samples.
    truth : Trajectory
        The truth samples the block read (its window, margins included).
    interpolants : SensorTruth
        The window's interpolants the device measured with; their body-frame methods
        (``attitude_world``, ``body_truth``, ``body_rates``) give the block's truth channels without
        building the splines again.
    """

    samples: ImuSamples
    truth: Trajectory
    interpolants: SensorTruth


class DeviceRun:
    """``device`` measuring the motion of ``source`` from power-up, as an iterator of blocks.

    Parameters
    ----------
    device : Device
    source : TruthSource
        The truth; its ``t_start`` is the power-up, its ``t_end`` (None: without end) bounds the samples.

    Attributes
    ----------
    first : int
        Index k of the first sample (1 without latencies; module notes of :mod:`gyroemu.sensors.imu`).
    count : int or None
        Number of samples, or None for a run without end.
    block_samples : int
        Output samples per block.

    Iterating yields :class:`MeasuredBlock` in time order; :meth:`samples` yields their samples only.
    """

    def __init__(self, device: Device, source: TruthSource) -> None:
        spec = device.spec
        self.device = device
        self.source = source
        self.period = 1.0 / spec.rate_hz  # what the device believes
        self.true_period = spec.clock.true_period(spec.rate_hz)
        self.t0 = float(source.t_start)
        latencies = device.latencies
        self._lag = max(0.0, *latencies)
        self._lead = min(0.0, *latencies)
        if latencies == (0.0, 0.0, 0.0):
            self.first = 1
        else:
            # K₁ = 1 + ceil(L_max / T'), K₂ = floor((t_end − t₀ + L_min) / T'): every sensor's shifted
            # interval [τ_{k−1} − L, τ_k − L] within the truth's span (module notes of imu).
            self.first = 1 + int(math.ceil(self._lag / self.true_period * (1 - 1e-12)))
        self.count: int | None = None
        if source.t_end is not None:
            span = source.t_end - self.t0 + self._lead
            self.count = int(math.floor(span / self.true_period * (1 + 1e-12))) - self.first + 1
            if self.count < 2:
                raise ConfigError(
                    f"the trajectory ({source.t_end - self.t0:g} s) is shorter than two samples of the device "
                    f"({self.period:g} s)" + (" and its sensors' latencies" if any(latencies) else ""),
                    key="duration",
                )
        # The inner grid: m steps per output interval, enough for the mechanism's inner rate and never
        # coarser than the truth's samples.
        self.substeps = max(1, math.ceil(self.true_period / source.step_s * (1 - 1e-9)))
        inner = math.ceil(device.inner_rate_hz / spec.rate_hz - 1e-9)
        self.inner_steps = max(self.substeps, inner)
        start = self.t0 + (self.first - 1) * self.true_period  # τ_{K₁−1}
        self.inner_step_s = (self.t0 + self.first * self.true_period - start) / self.inner_steps
        self.block_samples = max(1, min(BLOCK_MAX_SAMPLES, BLOCK_INNER_SAMPLES // self.inner_steps))

    def __iter__(self) -> Iterator[MeasuredBlock]:
        device = self.device
        streams = [np.random.default_rng(s) for s in np.random.SeedSequence(device.seed).spawn(5)]
        rng_clock, rng_mech, rng_gyro, rng_accel, rng_mag = streams
        gyro_errors = SensorErrors(device.gyro_errors, self.true_period, rng_gyro)
        others = _OtherSensors(rng_clock, SensorErrors(device.accel_errors, self.true_period, rng_accel), rng_mag)
        mechanism_state: dict[str, Any] = {}
        increment = device.spec.output == "increment"
        for block in self._blocks_ahead(others):
            increments, raw = self._gyro_increments(block.gyro_truth, len(block.stamps), rng_mech, mechanism_state)
            gyro = gyro_errors.apply(
                increments / self.period,
                block.instants[1:] - self.t0,  # from power-up: the rate ramp is R (τ_k − t₀)
                temperature_degC=block.temperature,
                specific_force=block.gyro_force_mean,
            )
            samples = ImuSamples(
                t=block.stamps,
                gyro=gyro,
                accel=block.accel,
                mag=block.mag,
                raw={device.kind: raw} if raw else {},
                delta_angle=gyro * self.period if increment else None,
                delta_velocity=block.accel * self.period if increment else None,
                t_true=block.instants[1:],
                temperature_degC=block.temperature,
                device=device.name,
            )
            yield MeasuredBlock(samples, block.window, block.truth)

    def _blocks_ahead(self, others: _OtherSensors) -> Iterator[_BlockReading]:
        """Each block's :meth:`_read`, in order; with more than one block, each is read on a worker
        thread while the caller runs the gyro's mechanism over the one before. The worker reads the
        blocks one after another, and the clock's, accelerometer's and magnetometer's states and
        generators are used there only, so they carry from block to block as they would in line: the
        same bytes."""
        starts: Iterator[int] = itertools.count(0, self.block_samples)
        if self.count is not None:
            starts = iter(range(0, self.count, self.block_samples))
        first = next(starts, None)
        if first is None:
            return
        if self.count is not None and self.count <= self.block_samples:  # one block: nothing to overlap
            yield self._read(others, first)
            return
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gyroemu-block") as pool:
            pending = pool.submit(self._read, others, first)
            try:
                for done in starts:
                    block = pending.result()
                    pending = pool.submit(self._read, others, done)
                    yield block
                yield pending.result()
            finally:
                pending.cancel()  # a consumer that stops early: the block in hand is dropped

    def _read(self, others: _OtherSensors, done: int) -> _BlockReading:
        """The block of samples ``done …`` but for its gyro: its instants, truth window and
        interpolants, temperature, the gyro mechanism's truth on its inner grid; the stamps (clock),
        the accelerometer's samples (and the mean specific force they measure) and the
        magnetometer's, each sensor at its latency."""
        spec = self.device.spec
        n = self.block_samples if self.count is None else min(self.block_samples, self.count - done)
        k = np.arange(self.first + done, self.first + done + n)
        instants = self.t0 + np.arange(k[0] - 1, k[-1] + 1) * self.true_period  # τ_{k−1} … τ_k
        window = self.source.window(float(instants[0]) - self._lag, float(instants[-1]) - self._lead)
        truth = SensorTruth(window, spec.mounting.q_bs, spec.mounting.lever_arm_m)
        temperature = spec.temperature.at(instants[1:] - self.t0)
        latency_gyro, latency_accel, latency_mag = self.device.latencies
        # k (int64) times a float is float64, which numpy's stubs type as floating[Any]
        stamps = cast("NDArray[np.float64]", k * self.period + spec.clock.offset_s)
        if spec.clock.jitter_s > 0:
            stamps = stamps + spec.clock.jitter_s * others.rng_clock.standard_normal(n)
        force_instants = instants if latency_accel == 0.0 else instants - latency_accel
        force_mean = mean_specific_force(truth, force_instants, substeps=self.substeps + self.substeps % 2)
        accel = others.accel_errors.apply(
            force_mean * (self.true_period / self.period), instants[1:] - self.t0, temperature_degC=temperature
        )
        # The gyro's g-sensitivity reads the force the gyro feels, at its own latency (τ − L_g).
        gyro_force_mean = None
        if self.device.gyro_errors.g_sensitivity is not None:
            gyro_force_mean = force_mean
            if latency_gyro != latency_accel:
                gyro_instants = instants if latency_gyro == 0.0 else instants - latency_gyro
                gyro_force_mean = mean_specific_force(truth, gyro_instants, substeps=self.substeps + self.substeps % 2)
        if spec.magnetometer is not None:
            field_instants = instants[1:] if latency_mag == 0.0 else instants[1:] - latency_mag
            mag = spec.magnetometer.measure(truth.magnetic_field(field_instants), self.period, others.rng_mag)
        else:
            mag = np.full((n, 3), np.nan)
        return _BlockReading(
            stamps=stamps,
            instants=instants,
            window=window,
            truth=truth,
            temperature=temperature,
            gyro_truth=self._gyro_truth(truth, done, n, latency_gyro),
            gyro_force_mean=gyro_force_mean,
            accel=accel,
            mag=mag,
        )

    def samples(self) -> Iterator[ImuSamples]:
        """The blocks' samples, in time order."""
        for block in self:
            yield block.samples

    def _gyro_truth(self, truth: SensorTruth, done: int, n: int, latency: float) -> GyroTruth:
        """The gyro mechanism's truth for the block of samples ``done … done + n``: its inner grid
        ``τ_{K₁−1} + j h`` for the block's ``j`` (the first point the previous block's last), on the
        device's instants (clock, temperature); with a ``latency`` ``L``, the motion at ``t − L``."""
        device, m, h = self.device, self.inner_steps, self.inner_step_s
        j = np.arange(done * m, (done + n) * m + 1)
        # j (int64) times a float is float64, which numpy's stubs type as floating[Any]
        t = cast("NDArray[np.float64]", self.t0 + (self.first - 1) * self.true_period + j * h)
        seen = t if latency == 0.0 else t - latency  # the motion's instants
        omega, alpha = truth.omega_alpha(seen)
        reads = device.mechanism.reads
        return GyroTruth(
            t=t,
            dt=h,
            omega=omega,
            alpha=alpha,
            specific_force=truth.specific_force(seen) if "specific_force" in reads else None,
            q_is=truth.attitude_inertial(seen) if "q_is" in reads else None,
            temperature_degC=device.spec.temperature.at(t - self.t0) if "temperature_degC" in reads else None,
        )

    def _gyro_increments(
        self, chunk: GyroTruth, n: int, rng: np.random.Generator, state: dict[str, Any]
    ) -> tuple[NDArray[np.float64], dict[str, NDArray[Any]]]:
        """Indicated angle increments (n, 3) over the block's intervals, and its raw observables: the
        mechanism's response to ``chunk`` (:meth:`_gyro_truth`), carrying ``state``."""
        m, h = self.inner_steps, self.inner_step_s
        response = self.device.mechanism.respond(chunk, rng, state)
        if response.angle is not None:
            angle = response.angle - response.angle[0]
            increments = np.diff(angle[::m], axis=0)  # inner index 0, m, 2m, … are the block's τ_{k−1} … τ_k
        else:  # a rate: trapezoid on the inner grid (the mechanisms' bandwidth is far below 1/h)
            # scipy's cumulative_trapezoid(rate, dx=h, initial=0) sampled at 0, m, 2m, … and differenced,
            # in one compiled pass with the same arithmetic (the same bits).
            increments = np.empty((n, 3))
            _trapezoid_increments(np.ascontiguousarray(response.rate, dtype=float), h, m, increments)
        # Copies: a strided view would keep the mechanism's whole inner-grid arrays alive.
        raw = {name: np.array(np.asarray(values)[m::m]) for name, values in response.raw.items()}
        return increments, raw


@njit
def _trapezoid_increments(rate: NDArray[np.float64], dx: float, m: int, out: NDArray[np.float64]) -> None:
    """``np.diff(cumulative_trapezoid(rate, dx=dx, axis=0, initial=0)[::m], axis=0)`` into ``out`` (n, A):
    the running sum of ``(dx (y_{k+1} + y_k)) / 2`` in order, differenced every ``m`` samples."""
    n_inner, n_axes = rate.shape
    for a in range(n_axes):
        total = 0.0
        previous = 0.0
        for k in range(n_inner - 1):
            total += (dx * (rate[k + 1, a] + rate[k, a])) / 2.0
            if (k + 1) % m == 0:
                out[(k + 1) // m - 1, a] = total - previous
                previous = total


def concatenate_samples(blocks: list[ImuSamples]) -> ImuSamples:
    """One :class:`ImuSamples` of a run's blocks (in time order, same device)."""
    first = blocks[0]
    if len(blocks) == 1:
        return first

    def joined(name: str) -> NDArray[np.float64] | None:
        values = [getattr(b, name) for b in blocks]
        return None if values[0] is None else np.concatenate(values)

    raw = {
        kind: {name: np.concatenate([b.raw[kind][name] for b in blocks]) for name in observables}
        for kind, observables in first.raw.items()
    }
    return ImuSamples(
        t=np.concatenate([b.t for b in blocks]),
        gyro=np.concatenate([b.gyro for b in blocks]),
        accel=np.concatenate([b.accel for b in blocks]),
        mag=np.concatenate([b.mag for b in blocks]),
        raw=raw,
        delta_angle=joined("delta_angle"),
        delta_velocity=joined("delta_velocity"),
        t_true=joined("t_true"),
        temperature_degC=joined("temperature_degC"),
        device=first.device,
    )
