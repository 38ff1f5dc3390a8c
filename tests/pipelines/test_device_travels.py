"""The device travels with the data: ``gyroemu stream`` announces its device's resolved config on
``gyroemu/<device>/config`` (a queryable, and one put), and ``gyroemu record`` stores it in the device's
``gyroemu`` metadata record, so that a filter run on the recorded log starts from the device's noise.

The fast tests feed a :class:`Recorder` samples by hand (config before the device, after it, too late,
never); the slow one runs a stream and two recorders, one started before it and one after it.
"""

import json
import time

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from live_processes import free_port, procs  # noqa: E402,F401  (procs is a fixture)
from zenoh_samples import Sample  # noqa: E402

from gyroemu.dynamics import load_scenario  # noqa: E402
from gyroemu.pipelines.estimation.setup import noise_from_device, setup_from_metadata  # noqa: E402
from gyroemu.pipelines.formats.mcap_log import read_mcap  # noqa: E402
from gyroemu.pipelines.transport.record import Recorder  # noqa: E402
from gyroemu.pipelines.transport.stream import encode_run  # noqa: E402
from gyroemu.pipelines.transport.zenoh_io import config_fields, config_key, topic_to_key  # noqa: E402
from gyroemu.sensors import load_device  # noqa: E402

SCENARIO, DEVICE = "smooth_manoeuvre", "consumer_mems"


def _samples(device: str, n: int = 20) -> list:
    dev = load_device(DEVICE, seed=3)
    rows = encode_run(dev.measure(load_scenario(SCENARIO).simulate(duration=n / dev.spec.rate_hz)))
    return [Sample(topic_to_key(device, "/imu"), bytes(row)) for row in rows["/imu"]]


def _config(device: str) -> Sample:
    dev = load_device(DEVICE, seed=3)
    extra = json.dumps({"seed": "3", "scenario": load_scenario(SCENARIO).to_toml()}).encode()
    return Sample(config_key(device), dev.to_toml().encode(), extra)


def _record(path, feed, grace=1.0) -> Recorder:
    recorder = Recorder(path, config_grace_s=grace)
    for item in feed:
        if item == "wait":
            time.sleep(grace * 1.5)
            recorder.flush()
        else:
            recorder.add(item)
    recorder.close()
    return recorder


def test_config_fields_read_payload_and_attachment():
    sample = _config("imu0")
    fields = config_fields(sample.payload.to_bytes(), sample.attachment.to_bytes())
    assert set(fields) == {"device", "seed", "scenario"} and fields["seed"] == "3"
    assert config_fields(b"rate_hz = 100\n") == {"device": "rate_hz = 100\n"}
    with pytest.raises(ValueError):
        config_fields(b"not = = toml")


@pytest.mark.parametrize("order", ["config first", "config after data", "config too late"])
def test_recorder_stores_the_device_config(tmp_path, order):
    """However the config comes (before the first data, after it, after the grace period), the log's
    device carries it, and the filter setup read from the log is the device's."""
    data, config = _samples("dev_a"), _config("dev_a")
    feed = {
        "config first": [config, *data],
        "config after data": [*data[:5], config, *data[5:]],
        "config too late": [*data, "wait", config],
    }[order]
    path = tmp_path / "r.mcap"
    recorder = _record(path, feed, grace=0.2)
    assert recorder.messages == len(data) and recorder.configured == ["dev_a"]
    log = read_mcap(path)
    assert log.device.name == "dev_a"
    meta = log.device.metadata
    assert meta["seed"] == "3" and 'kind = "' in meta["scenario"]
    assert meta["device"] == load_device(DEVICE, seed=3).to_toml()
    setup = setup_from_metadata(meta, 100.0, use_mag=True)
    assert setup.noise == noise_from_device(load_device(DEVICE, seed=3))


def test_recorder_without_config_names_the_device_only(tmp_path):
    path = tmp_path / "r.mcap"
    recorder = _record(path, _samples("dev_b"), grace=0.2)
    assert recorder.configured == [] and recorder.devices == ["dev_b"]
    log = read_mcap(path)
    assert log.device.name == "dev_b" and log.device.metadata["device"] == ""
    assert len(log.metadata) == 1


@pytest.mark.slow
def test_stream_config_reaches_recorders_started_before_and_after(procs, tmp_path):
    """A recorder started before the stream and one started while it publishes both store the config;
    ``read_mcap`` then gives the device's config, seed and scenario."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs.start("before", "record", "--out", str(tmp_path / "before.mcap"), "--connect", endpoint)
    procs.wait_for("before", "subscribed")
    procs.start(
        "stream",
        "stream",
        "--scenario",
        SCENARIO,
        "--device",
        DEVICE,
        "--seed",
        "5",
        "--duration",
        "6",
        "--listen",
        endpoint,
        "--device-name",
        "trav",
    )
    procs.wait_for("stream", "publishing", timeout=60)
    procs.start("after", "record", "--out", str(tmp_path / "after.mcap"), "--connect", endpoint)
    assert procs.wait("stream", 60) == 0, procs.log("stream")
    time.sleep(0.5)
    for name in ("before", "after"):
        assert procs.stop(name) == 0, procs.log(name)
        assert "device config stored for trav" in procs.log(name), procs.log(name)
        log = read_mcap(tmp_path / f"{name}.mcap")
        meta = log.device.metadata
        assert log.device.name == "trav" and meta["seed"] == "5"
        assert meta["device"] == load_device(DEVICE, seed=5).to_toml()
        assert meta["scenario"] == load_scenario(SCENARIO).to_toml()
        assert np.isfinite(log.device.samples.gyro).all()
