"""The HTML report: one self-contained file, checked in headless chromium when installed."""

import re
import shutil
import subprocess

import pytest

import slipstep
from slipstep.study.report import write_report


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    path = tmp_path_factory.mktemp("report") / "paper.html"
    write_report(
        slipstep.load_system("paper"),
        path,
        periods=2,
        rotor_speed_rpm=3600,
        radius_m=0.5,
        displacement_amplitude_m=1e-7,
    )
    return path


def test_report_is_self_contained(report):
    text = report.read_text(encoding="utf-8")
    assert not re.search(r"https?://", text), "the report must not reference the network"
    assert not re.search(r"<(script|link)\b", text)
    imgs = re.findall(r"<img [^>]*src=\"([^\"]+)\"", text)
    assert len(imgs) >= 6
    assert all(src.startswith("data:image/png;base64,") and len(src) > 10_000 for src in imgs)


def test_report_tables(report):
    text = report.read_text(encoding="utf-8")
    for heading in ("Loads", "Loop energies", "Timings", "Method advisor", "Contact states"):
        assert heading in text
    # the quasi-static left-face energy of physics.md 6 (2.52 mJ) is in the table
    row = re.search(r"<td>quasi-static</td><td>left \(P1,P2\)</td><td>([0-9.]+)</td>", text)
    assert row and abs(float(row.group(1)) - 2.52) < 0.03
    assert "free of flutter" in text


def test_report_cli_bad_case(tmp_path):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    res = CliRunner().invoke(app, ["report", str(tmp_path / "nope.toml"), "--output", str(tmp_path / "x.html")])
    assert res.exit_code == 2


def test_report_in_headless_chromium(report, tmp_path):
    browser = shutil.which("chromium")
    if browser is None:
        pytest.skip("Debian's chromium is not installed (apt-get install -y chromium): browser check skipped")
    # a copy of the report with a probe that counts the images the browser actually decoded
    probe = (
        "<script>window.addEventListener('load', () => { document.body.setAttribute('data-decoded', "
        "[...document.images].filter(i => i.complete && i.naturalWidth > 0).length); });</script>"
    )
    page = tmp_path / "probe.html"
    page.write_text(report.read_text(encoding="utf-8").replace("</body>", probe + "</body>"), encoding="utf-8")
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--enable-logging=stderr",
        "--v=0",
        "--virtual-time-budget=5000",
        "--dump-dom",
        page.resolve().as_uri(),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    dom = proc.stdout
    n_img = len(re.findall(r"<img ", report.read_text(encoding="utf-8")))
    assert n_img >= 6 and len(re.findall(r"<img ", dom)) == n_img
    decoded = re.search(r'data-decoded="(\d+)"', dom)
    assert decoded and int(decoded.group(1)) == n_img, "some figures did not load in the browser"
    console = [line for line in proc.stderr.splitlines() if ":CONSOLE" in line or "Uncaught" in line]
    assert not console, console
    assert "net::ERR" not in proc.stderr
