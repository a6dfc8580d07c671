"""The rest of the tool from Python, each equal to the CLI's run of the same test: a real-time
run, a lab target against `substep lab emulate`, a remote site served by `substep site serve`,
and the live monitor page (read and driven by headless Chromium through chromedriver, as the
CLI's own monitor test does)."""

import csv
import json
import os
import socket
import subprocess
import threading
import time
import urllib.request
from pathlib import Path

import pytest

import substep
from conftest import ROOT, run_cli

DEFAULT = (ROOT / "examples" / "default.toml").read_text()


def _table(path: Path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], [[float(x) for x in r] for r in rows[1:]]


def _worst_relative(a: Path, b: Path) -> float:
    """Largest |a − b| over the columns both tables have, relative to each column's peak |b|."""
    (na, ra), (nb, rb) = _table(a), _table(b)
    assert len(ra) == len(rb), (a, b)
    worst = 0.0
    for name in set(na) & set(nb):
        ia, ib = na.index(name), nb.index(name)
        peak = max(abs(r[ib]) for r in rb) or 1.0
        worst = max(worst, max(abs(x[ia] - y[ib]) for x, y in zip(ra, rb)) / peak)
    return worst


def test_a_realtime_run_from_python_equals_the_cli_realtime_run(cli, tmp_path):
    cfg = tmp_path / "short.toml"
    cfg.write_text(DEFAULT.replace("duration = 20.0", "duration = 2.0"))
    proc = run_cli(cli, "run", str(cfg), "--realtime", "--out", str(tmp_path / "cli"), "--quiet")
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(cli, "run", str(cfg), "--out", str(tmp_path / "offline"), "--quiet", "--no-plots")
    assert proc.returncode == 0, proc.stderr

    started = time.monotonic()
    result = substep.run(cfg, realtime=True, out_dir=tmp_path / "py")
    wall = time.monotonic() - started
    assert wall >= 2.0, f"2 s of test time in {wall:.2f} s of wall time: not paced by the clock"
    s = result.summary
    assert s["mode"] == "realtime" and s["completed"] and s["real_time"], s
    assert s["missed_share"] <= s["max_missed"]
    names = sorted(p.name for p in (tmp_path / "py").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert names == ["history.csv", "realtime.json", "realtime.txt", "summary.json"]
    cli_summary = json.loads((tmp_path / "cli" / "summary.json").read_text())
    assert sorted(cli_summary) == sorted(s)
    for key in ("steps", "steps_done", "dt", "completed", "real_time"):
        assert cli_summary[key] == s[key], key
    # The virtual test does not depend on the clock: both real-time runs are the offline run.
    py_h, cli_h = tmp_path / "py" / "history.csv", tmp_path / "cli" / "history.csv"
    assert py_h.read_text().split("\n", 1)[0] == cli_h.read_text().split("\n", 1)[0]
    assert _worst_relative(py_h, tmp_path / "offline" / "history.csv") < 1e-9
    assert _worst_relative(cli_h, tmp_path / "offline" / "history.csv") < 1e-9
    # the Result holds the file's table
    assert result.history.values.shape == (201, len(result.history.names))
    assert s["reference"]["max_displacement_error"] == pytest.approx(
        cli_summary["reference"]["max_displacement_error"], rel=1e-9)


def test_realtime_options_are_checked(tmp_path):
    cfg = tmp_path / "short.toml"
    cfg.write_text(DEFAULT.replace("duration = 20.0", "duration = 0.5"))
    with pytest.raises(substep.ConfigError, match="give realtime=True"):
        substep.run(cfg, max_missed=0.1)
    with pytest.raises(substep.ConfigError, match="max_missed"):
        substep.run(cfg, realtime=True, out_dir=tmp_path / "a", max_missed=2.0)
    with pytest.raises(substep.ConfigError, match="late_policy"):
        substep.run(cfg, realtime=True, out_dir=tmp_path / "b", late_policy="never")
    with pytest.raises(TypeError, match="max_missed: must be"):
        substep.run(cfg, realtime=True, max_missed="1 %")
    with pytest.raises(substep.ConfigError, match="pace"):
        substep.run(cfg, realtime=True, pace=1.0)
    mono = tmp_path / "mono.toml"
    mono.write_text((ROOT / "examples" / "monolithic_tmd.toml").read_text().replace(
        'file = "', f'file = "{ROOT / "examples"}/'))
    with pytest.raises(substep.ConfigError, match="realtime=True: needs a \\[substructure\\]"):
        substep.run(mono, realtime=True, out_dir=tmp_path / "c")
    assert not any((tmp_path / d).exists() for d in "abc")


def _spawn(cli: Path, args, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([str(cli), *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _emulate(cli: Path, d: Path, name: str) -> (subprocess.Popen, int):
    """`substep lab emulate` for the test `name.toml` in `d`; returns the process and its port."""
    (d / f"{name}.emu.toml").write_text(f'test = "{name}.toml"\nidle = 20.0\n')
    p = _spawn(cli, ["lab", "emulate", f"{name}.emu.toml", "--bind", "127.0.0.1:0"], d)
    line = p.stdout.readline()
    assert line.startswith("lab emulator: "), line + p.stderr.read()
    return p, int(line.split("127.0.0.1:")[1].split(" ")[0])


def _lab_config(port: int) -> str:
    return (DEFAULT.replace("duration = 20.0", "duration = 2.0")
            + f'\n[substructure.lab]\nprotocol = "generic_tcp"\ntransport = "tcp"\naddress = "127.0.0.1:{port}"\n')


@pytest.mark.parametrize("realtime", [False, True], ids=["offline", "realtime"])
def test_a_lab_target_from_python_equals_the_cli_run_against_the_emulator(cli, tmp_path, realtime):
    outs = {}
    for front in ("cli", "py"):
        name = f"lab_{front}"
        cfg = tmp_path / f"{name}.toml"
        cfg.write_text(_lab_config(9))  # the emulator reads protocol and channels; the address is its own
        emulator, port = _emulate(cli, tmp_path, name)
        try:
            cfg.write_text(_lab_config(port))
            out = tmp_path / front
            more = ["--realtime"] if realtime else ["--no-plots"]
            if front == "cli":
                proc = run_cli(cli, "run", str(cfg), "--out", str(out), "--quiet", *more)
                assert proc.returncode == 0, proc.stderr
            else:
                r = substep.run(cfg, out_dir=out, realtime=realtime, **({} if realtime else {"plots": False}))
                assert r.completed
                assert r.summary["lab"]["exchanges"] > 0, r.summary["lab"]
            assert emulator.wait(timeout=30) == 0, emulator.stderr.read()
        finally:
            if emulator.poll() is None:
                emulator.kill()
        outs[front] = out
    names = sorted(p.name for p in outs["py"].iterdir())
    assert names == sorted(p.name for p in outs["cli"].iterdir())
    assert "history.csv" in names
    if realtime:
        assert _worst_relative(outs["py"] / "history.csv", outs["cli"] / "history.csv") < 1e-9
    else:
        for n in names:
            if n.endswith(".csv"):
                assert (outs["py"] / n).read_bytes() == (outs["cli"] / n).read_bytes(), n


SITE_SPECIMEN = """
[[specimen]]
kind = "linear_sdof"
dof = 1
mass = 10.0
stiffness = 5000.0
damping = 30.0
"""


def _serve(cli: Path, d: Path) -> (subprocess.Popen, str):
    (d / "site.toml").write_text('[site]\nprotocol = "substep"\nlisten = "127.0.0.1:0"\n' + SITE_SPECIMEN)
    env = {k: v for k, v in os.environ.items() if k != "SUBSTEP_SITE_SECRET"}
    p = subprocess.Popen([str(cli), "site", "serve", "site.toml", "--once"], cwd=d, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    assert "listening on tcp://127.0.0.1:" in line, line + p.stderr.read()
    return p, line.strip().rsplit("tcp://", 1)[1]


def _remote_config(addr: str) -> str:
    base = """
[structure]
mass = [[2000.0, 0.0], [0.0, 1000.0]]
stiffness = [[1.2e5, -5.0e4], [-5.0e4, 5.0e4]]
damping = [[800.0, -300.0], [-300.0, 300.0]]

[ground_motion]
generator = "sine_sweep"
amplitude = 1.0
f0 = 0.3
f1 = 3.0
duration = 2.0

[integrator]
scheme = "average_acceleration"
dt = 0.01

[substructure]
coupling_dofs = [1]
substeps = 4
"""
    return base + f'\n[substructure.remote]\naddress = "{addr}"\nmode = "per_substep"\ntimeout = 1.0\n'


def test_a_remote_site_from_python_equals_the_cli_run(cli, tmp_path):
    outs = {}
    for front in ("cli", "py"):
        site, addr = _serve(cli, tmp_path)
        try:
            cfg = tmp_path / f"remote_{front}.toml"
            cfg.write_text(_remote_config(addr))
            out = tmp_path / front
            if front == "cli":
                proc = run_cli(cli, "run", str(cfg), "--out", str(out), "--quiet")
                assert proc.returncode == 0, proc.stderr
            else:
                assert substep.run(cfg, out_dir=out).completed
            assert site.wait(timeout=30) == 0, site.stderr.read()
        finally:
            if site.poll() is None:
                site.kill()
        outs[front] = out
    names = sorted(p.name for p in outs["py"].iterdir())
    assert names == sorted(p.name for p in outs["cli"].iterdir())
    assert {"history.csv", "substeps.csv"} <= set(names)
    for n in names:
        if n.endswith(".csv"):
            assert (outs["py"] / n).read_bytes() == (outs["cli"] / n).read_bytes(), n


# --- the live monitor page -------------------------------------------------------------------

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _http(port: int, method: str, path: str, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=data, method=method,
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as r:
        return json.loads(r.read() or b"null")


class _Browser:
    """A headless Chromium session through chromedriver's W3C WebDriver HTTP API."""

    def __init__(self, profile: Path):
        self.port = _free_port()
        self.driver = subprocess.Popen([CHROMEDRIVER, f"--port={self.port}"], stdout=subprocess.DEVNULL,
                                       stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 20
        while True:
            try:
                _http(self.port, "GET", "/status")
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        caps = {"capabilities": {"alwaysMatch": {"goog:chromeOptions": {
            "binary": CHROMIUM,
            "args": ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                     "--disable-background-networking", "--window-size=1400,1100",
                     f"--user-data-dir={profile}"]}}}}
        self.session = _http(self.port, "POST", "/session", caps)["value"]["sessionId"]

    def cmd(self, method: str, path: str, body=None):
        return _http(self.port, method, f"/session/{self.session}{path}", body)["value"]

    def element(self, css: str) -> str:
        found = self.cmd("POST", "/element", {"using": "css selector", "value": css})
        assert isinstance(found, dict) and found, f"no element {css}: {found}"
        return next(iter(found.values()))

    def text(self, css: str) -> str:
        return self.cmd("GET", f"/element/{self.element(css)}/text")

    def wait_for(self, seconds: float, what: str, ok):
        deadline = time.monotonic() + seconds
        while not ok():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            time.sleep(0.1)

    def close(self):
        try:
            _http(self.port, "DELETE", f"/session/{self.session}")
        except OSError:
            pass
        self.driver.kill()


@pytest.mark.skipif(not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)),
                    reason="chromium / chromium-driver not installed (.ci/run installs them)")
def test_the_monitor_page_of_a_python_run_shows_live_data_and_stops_it_with_the_token(tmp_path):
    port, token = _free_port(), "0123456789abcdef-token"
    outcome = {}

    def run():
        try:
            outcome["result"] = substep.run(ROOT / "examples" / "default.toml", out_dir=tmp_path / "out",
                                            plots=False, pace=1.0, monitor=f"127.0.0.1:{port}",
                                            monitor_token=token, monitor_linger=2.0)
        except substep.RunError as e:
            outcome["error"] = e

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    deadline = time.monotonic() + 20
    while True:
        try:
            _http(port, "GET", "/state")
            break
        except OSError:
            assert time.monotonic() < deadline, "the monitor did not come up"
            time.sleep(0.1)
    browser = _Browser(tmp_path / "profile")
    try:
        browser.cmd("POST", "/url", {"url": f"http://127.0.0.1:{port}/"})
        browser.wait_for(20, "live data on the page", lambda: browser.text("#step") != "–")
        s1 = int(browser.text("#step"))
        time.sleep(0.7)
        s2 = int(browser.text("#step"))
        assert s2 > s1, f"the page did not update: step {s1} then {s2}"
        # without the token the stop is refused and the run goes on
        browser.cmd("POST", f"/element/{browser.element('#stop')}/click", {})
        browser.wait_for(10, "the refusal", lambda: "refused" in browser.text("#reply"))
        assert _http(port, "GET", "/state")["finished"] is None
        # with it, the controlled stop
        browser.cmd("POST", f"/element/{browser.element('#token')}/value", {"text": token})
        browser.cmd("POST", f"/element/{browser.element('#stop')}/click", {})
        browser.wait_for(30, "the final state on the page", lambda: browser.text("#status").startswith("finished"))
        assert "operator" in browser.text("#final_text")
    finally:
        browser.close()
    worker.join(timeout=30)
    assert not worker.is_alive(), "the Python run did not end after the stop"
    err = outcome.get("error")
    assert err is not None, "a stopped run raises RunError"
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["completed"] is False and summary["stopped_by"] == "operator"
    assert summary["ramp_substeps"] == 400, "1 s ramp in sub-steps of 2.5 ms"
    assert err.result.summary["stopped_by"] == "operator"
    assert s2 < summary["steps_done"] < 2000


def test_bad_monitor_options_are_refused_naming_the_keyword(tmp_path):
    example = ROOT / "examples" / "default.toml"
    with pytest.raises(substep.ConfigError, match="monitor: 0.0.0.0:8080 is not a loopback address.*monitor_public=True"):
        substep.run(example, monitor="0.0.0.0:8080")
    with pytest.raises(substep.ConfigError, match="monitor_token"):
        substep.run(example, monitor="127.0.0.1:0", monitor_token="short")
    with pytest.raises(substep.ConfigError, match="monitor: 'nowhere' is not an address"):
        substep.run(example, monitor="nowhere")
    with pytest.raises(substep.ConfigError, match="stability"):
        substep.run(example, stability="sometimes")
    with pytest.raises(substep.ConfigError, match="monitor_linger"):
        substep.run(example, monitor="127.0.0.1:0", monitor_linger=-1.0)
    with pytest.raises(TypeError, match="monitor: must be a str"):
        substep.run(example, monitor=8080)
