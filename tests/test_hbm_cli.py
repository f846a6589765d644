"""The command-line side of the harmonic balance: --harmonics / --frequencies parsing, the
run (progress bar, netCDF written atomically, figure, summary with the cross-check)."""

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hbm_cases import jenkins_1dof
from rich.console import Console

import slipstep as ss
from slipstep.frequency.response import check_frequencies, parse_frequencies
from slipstep.cli.hbm import parse_harmonics, run_command


def test_parse_harmonics_and_frequencies():
    assert parse_harmonics("1,3,5") == (1, 3, 5)
    assert parse_harmonics("15") == 15
    assert np.allclose(parse_frequencies("150:450:61"), np.linspace(150, 450, 61))
    assert np.allclose(parse_frequencies("450:150:3"), [450, 300, 150])
    for bad in ("", "a,b", "0", "-1,3"):
        with pytest.raises(ss.InputError) as err:
            parse_harmonics(bad)
        assert err.value.field == "--harmonics"
    for bad in ("150:450", "150:450:0", "x"):
        with pytest.raises(ss.InputError) as err:
            parse_frequencies(bad)
        assert err.value.field == "--frequencies"
    with pytest.raises(ss.InputError) as err:
        check_frequencies(parse_frequencies("-5,10"))
    assert err.value.field == "frequencies"


def test_run_command_writes_the_result_figure_and_summary(tmp_path):
    with open(tmp_path / "out.txt", "w") as fh:
        ds, s = run_command(
            jenkins_1dof(),
            parse_frequencies("250:400:7"),
            harmonics="1,3,5,7",
            output=tmp_path / "h.nc",
            plot_path=tmp_path / "h.png",
            console=Console(file=fh, width=120),
        )
    back = xr.open_dataset(tmp_path / "h.nc", engine="h5netcdf")
    assert np.allclose(back.amplitude.values, ds.amplitude.values) and back.attrs["solver"] == "hbm"
    assert (tmp_path / "h.png").stat().st_size > 10_000
    assert s["points"] == ds.frequency.size and 300 < s["peak_frequency_Hz"] < 340
    check = s["checks"][0]
    assert check["march_status"] == "OK" and check["amplitude_rel_diff"] < 0.01
    text = (tmp_path / "out.txt").read_text()
    assert "cross-check at" in text and "amplitude diff" in text
    json.dumps(s)  # the --json summary is serialisable


def _cli(*args):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    return CliRunner().invoke(app, list(args))


JENKINS_TOML = str(Path(__file__).resolve().parents[1] / "examples" / "jenkins.toml")


def test_cli_frf_solver_hbm(tmp_path):
    result = _cli(
        "frf",
        JENKINS_TOML,
        "--frequencies",
        "250:400:7",
        "--solver",
        "hbm",
        "--harmonics",
        "1,3,5,7",
        "--check-frequencies",
        "380",
        "-o",
        str(tmp_path),
        "--json",
    )
    assert result.exit_code == 0, result.output
    s = json.loads(result.output.strip().splitlines()[-1])
    assert s["solver"] == "hbm" and s["harmonics"] == [0, 1, 3, 5, 7] and s["points_not_ok"] == 0
    assert len(s["checks"]) == 2 and all(c["march_status"] == "OK" for c in s["checks"])
    assert all(c["amplitude_rel_diff"] < 0.01 for c in s["checks"])
    ds = xr.open_dataset(s["output"], engine="h5netcdf")
    assert ds.attrs["solver"] == "hbm" and np.isfinite(ds.check_amplitude_rel_diff.values).sum() == 2
    assert Path(s["figure"]).stat().st_size > 10_000


@pytest.mark.parametrize(
    "args, field",
    [
        (("--solver", "hbm", "--harmonics", "1,x"), "--harmonics"),
        (("--solver", "march", "--harmonics", "1,3,5"), "--harmonics"),
    ],
)
def test_cli_frf_bad_harmonics(tmp_path, args, field):
    result = _cli("frf", JENKINS_TOML, "--frequencies", "250:400:3", *args, "-o", str(tmp_path))
    assert result.exit_code == 2
    assert field in result.output
