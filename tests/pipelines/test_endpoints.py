"""Live commands say clearly when their zenoh endpoints do not work: a ``--listen`` endpoint another
program holds (exit status 2, ``argument --listen: ... is taken by another program``), and a
``--connect`` endpoint where no router answers (a client: exit status 2; a peer: a warning, since zenoh
keeps trying in the background)."""

import socket
import subprocess
import sys

import pytest

pytest.importorskip("zenoh")

from gyroemu.pipelines.transport.zenoh_io import port_is_free  # noqa: E402


def gyroemu(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gyroemu", *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def held_port():
    """A port a plain socket listens on (a program that speaks no zenoh)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


@pytest.mark.parametrize("command", ["router", "record"])
def test_listen_on_a_port_held_by_another_program_exits_2(held_port, tmp_path, command):
    endpoint = f"tcp/127.0.0.1:{held_port}"
    extra = ["--out", str(tmp_path / "r.mcap"), "--duration", "1"] if command == "record" else []
    result = gyroemu(command, "--listen", endpoint, *extra)
    assert result.returncode == 2, result.stderr
    assert f"gyroemu {command}: error: argument --listen: {endpoint} is taken by another program " in result.stderr
    assert "(not a zenoh router)" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "r.mcap").exists()


def test_stream_names_a_taken_port_before_any_work(held_port):
    """``stream`` opens its session before it computes or announces anything: a taken --listen port is
    the only thing it says (it was said after the first block was computed and the stream announced)."""
    endpoint = f"tcp/127.0.0.1:{held_port}"
    result = gyroemu("stream", "--scenario", "heavy_top", "--device", "consumer_mems", "--listen", endpoint)
    assert result.returncode == 2, result.stderr
    assert f"argument --listen: {endpoint} is taken by another program" in result.stderr
    assert result.stdout == "" and "Traceback" not in result.stderr


def test_port_is_free(held_port):
    assert port_is_free(f"tcp/127.0.0.1:{held_port}") is False
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        free = s.getsockname()[1]
    assert port_is_free(f"tcp/127.0.0.1:{free}") is True
    assert port_is_free("udp/127.0.0.1:7447") is None


def test_client_connect_where_no_router_answers_exits_2(tmp_path):
    with socket.socket() as s:  # a port nobody listens on: the connection is refused at once
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tcp/127.0.0.1:{port}"
    result = gyroemu("record", "--out", str(tmp_path / "r.mcap"), "--connect", endpoint, "--mode", "client")
    assert result.returncode == 2, result.stderr
    assert f"argument --connect: no zenoh router answers at {endpoint}" in result.stderr, result.stderr


def test_peer_connect_where_nothing_answers_warns(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tcp/127.0.0.1:{port}"
    result = gyroemu("record", "--out", str(tmp_path / "r.mcap"), "--connect", endpoint, "--duration", "0.5")
    assert result.returncode == 0, result.stderr
    assert f"record: warning: nothing answers at --connect {endpoint} yet" in result.stdout, result.stdout


@pytest.mark.parametrize("option", ["--connect", "--listen"])
@pytest.mark.parametrize(
    "endpoint, why",
    [("garbage", "is not a zenoh endpoint"), ("tcp/", "is not a zenoh endpoint"), ("tcp/host", "has no port")],
)
def test_a_malformed_endpoint_is_named_with_the_form_of_one(tmp_path, monkeypatch, option, endpoint, why):
    """``--connect garbage`` printed zenoh's ``Json5Err(Message {...})`` under "--connect/--listen/--mode":
    the option is named, and what an endpoint looks like said, before any session is opened."""
    from cli_runs import run_cli

    from gyroemu.pipelines.transport import record
    from gyroemu.pipelines.transport.zenoh_io import LiveOptionError, session_config

    monkeypatch.setattr(record, "open_session", lambda *a, **k: pytest.fail("a session was opened"))
    code, _, stderr = run_cli(["record", "--out", str(tmp_path / "r.mcap"), "--duration", "1", option, endpoint])
    assert code == 2, stderr
    assert f"gyroemu record: error: argument {option}: {endpoint!r} {why}" in stderr, stderr
    assert "an endpoint looks like PROTOCOL/ADDRESS, e.g. tcp/HOST:PORT" in stderr and "Json5Err" not in stderr
    with pytest.raises(LiveOptionError, match=f"argument {option}: "):
        session_config(**{option[2:]: [endpoint]})
    assert list(tmp_path.iterdir()) == []


def test_well_formed_endpoints_are_taken():
    from gyroemu.pipelines.transport.zenoh_io import session_config

    for endpoint in ("tcp/127.0.0.1:7447", "tcp/[::1]:0", "tcp/localhost:7447#iface=lo", "udp/224.0.0.224:7446"):
        session_config(connect=[endpoint], listen=[endpoint])


def test_a_router_listens_where_its_config_file_says(tmp_path):
    """``router --config FILE``: the file's listen endpoints stand (the router put tcp/0.0.0.0:7447 over
    them); --listen stands over the file; with neither, or a file that sets none, the router's default."""
    import json

    from gyroemu.pipelines.transport.zenoh_io import router_config

    own = tmp_path / "own.json5"
    own.write_text('{ listen: { endpoints: ["tcp/127.0.0.1:17999"] } }')
    silent = tmp_path / "silent.json5"
    silent.write_text('{ mode: "router" }')

    def listening(**options):
        return json.loads(router_config(**options).get_json("listen/endpoints"))

    assert listening(config_file=own) == ["tcp/127.0.0.1:17999"]
    assert listening(config_file=own, listen=["tcp/127.0.0.1:18000"]) == ["tcp/127.0.0.1:18000"]
    assert listening(config_file=silent) == listening() == ["tcp/0.0.0.0:7447"]


def test_a_live_estimate_beside_a_stream_that_listens(tmp_path):
    """``stream --listen X --estimate``: the live filter's own session connects to X instead of listening
    on it too (it was refused as 'taken by a zenoh process', the stream's own session, after the first
    block); the filter publishes (how many depends on when its session links up: the stream waits for
    no subscriber here)."""
    import re

    from live_processes import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argv = ["--scenario", "rate_table_constant", "--device", "consumer_mems", "--duration", "1"]
    result = gyroemu("stream", *argv, "--as-fast-as-possible", "--wait", "0", "--listen", endpoint, "--estimate")
    assert result.returncode == 0, result.stderr
    published = re.search(r"stream: (\d+) estimates published", result.stdout)
    assert published is not None and int(published.group(1)) > 0, result.stdout
