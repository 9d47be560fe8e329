"""Bad input to a modal fit: one clear line (a ValueError in the library, exit 2 from ``labkit fit``),
never a traceback or a "mode" fitted to nothing; and ``labkit fit`` of an FRF file that is not a
labkit run writes the fitted modes, not a robot parameter file, unless a mapping is given."""
from __future__ import annotations

import tomllib

import numpy as np
import pytest

from clihelpers import last_json, run_cli
from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.synth import synthetic_frf
from labkit.errors import InputError

F = np.linspace(100.0, 1000.0, 400)
H = synthetic_frf(F, [500.0], [0.01], noise=0.01, seed=1)[0]


@pytest.mark.parametrize("freq, frf, message", [
    (np.zeros(0), np.zeros(0, complex), "empty"),
    ([], [], "no FRF"),
    (F, np.full(F.size, 1 + 2j), "constant"),
    (F, np.full(F.size, 3.0), "constant"),
    (np.r_[F, F[:5]], np.r_[H, H[:5]], "appears more than once"),
    (np.r_[F, F[200]], np.r_[H, H[0]], f"frequency {F[200]:g} appears more than once"),
])
def test_bad_arrays_are_one_line_value_errors(freq, frf, message):
    with pytest.raises(ValueError, match=message) as exc:
        fit_modes(freq, frf)
    assert isinstance(exc.value, InputError)            # exit code 2 from the command line
    assert "\n" not in str(exc.value)


def test_a_list_of_complex_numbers_is_one_frf_not_one_location_per_number():
    as_list = fit_modes(F, list(H))
    as_array = fit_modes(F, H)
    assert as_list.locations == ["0"]
    assert [m.freq_hz for m in as_list.modes] == [m.freq_hz for m in as_array.modes]
    assert as_list.modes[0].freq_hz == pytest.approx(500.0, rel=1e-3)


def _csv(path, f, h):
    np.savetxt(path, np.column_stack([f, h.real, h.imag]), delimiter=",", header="f,re,im", comments="")
    return path


def test_cli_duplicated_lines_exit_2_with_one_line(tmp_path):
    path = _csv(tmp_path / "dup.csv", np.r_[F, F[10]], np.r_[H, H[10]])
    proc = run_cli("fit", str(path), "--columns", "f=f,re=re,im=im", "--out", str(tmp_path / "m.toml"), check=2)
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "appears more than once" in err[0] and "Traceback" not in proc.stderr, proc.stderr
    assert not (tmp_path / "m.toml").exists()


def test_cli_generic_frf_writes_modes_only_unless_a_mapping_is_given(tmp_path):
    path = _csv(tmp_path / "frf.csv", F, H)
    out = tmp_path / "modes.toml"
    s = last_json(run_cli("fit", str(path), "--columns", "f=f,re=re,im=im", "--out", str(out), "--no-figures",
                          "--json"))
    assert s["modes_only"] is True
    table = tomllib.loads(out.read_text())
    assert set(table) == {"modes", "provenance"}             # no robot parameters at all
    assert table["modes"][0]["freq_hz"] == pytest.approx(500.0, rel=1e-3)
    assert table["modes"][0]["freq_hz"] == s["fitted_modes"][0]["freq_hz"]
    # with an explicit mapping: a robot parameter file with the fitted mode as simulator mode 2
    robot = tmp_path / "robot.toml"
    s2 = last_json(run_cli("fit", str(path), "--columns", "f=f,re=re,im=im", "--out", str(robot), "--assign",
                           "2=#1", "--no-figures", "--json"))
    assert s2["modes_only"] is False
    from labkit.sim import RobotParams

    p = RobotParams.from_toml(robot)
    assert p.modal_freq_hz[1] == pytest.approx(s2["fitted_modes"][0]["freq_hz"], rel=1e-12)
    assert p.modal_freq_hz[0] == pytest.approx(RobotParams().modal_freq_hz[0])
