"""The tray's amplitude law as data (labkit.sim.paper.shaker.TableLaw, load_tray_law)."""
from __future__ import annotations

import pytest

from labkit.errors import InputError
from labkit.sim.paper.shaker import PAPER_SHAKER, TableLaw, load_tray_law
from labkit.sim.scenarios import run_scenario


def test_log_log_interpolation_is_exact_for_a_power_law(tmp_path):
    """A mass-controlled shaker (constant acceleration) has amplitude ~ 1/f^2: two points of it
    give it exactly in between; the drive scales it linearly."""
    f = tmp_path / "t.csv"
    f.write_text("# measured transmissibility\n# drive_vpp = 4\nfreq_hz,amp_um\n200,36\n400,9\n", encoding="utf-8")
    law = load_tray_law(str(f))
    assert law.ref_drive_vpp == 4.0 and law.freqs_hz == (200.0, 400.0)
    for fr in (200.0, 283.0, 400.0):
        assert law.amp_um(fr) == pytest.approx(36.0 * (200.0 / fr) ** 2, rel=1e-12)
    assert law.amp_um(300.0, 8.0) == pytest.approx(2 * 16.0, rel=1e-12)
    assert law.describe()["source"] == str(f) and law.describe()["law"] == "table"


def test_toml_table_and_the_paper_law_as_data(tmp_path):
    freqs = [150.0, 200.0, 240.0, 300.0, 500.0, 1000.0]
    f = tmp_path / "t.toml"
    f.write_text(f"drive_vpp = 8.0\nfreq_hz = {freqs}\namp_um = {[PAPER_SHAKER.amp_um(x) for x in freqs]}\n",
                 encoding="utf-8")
    law = load_tray_law(str(f))
    for x in freqs:
        assert law.amp_um(x, 6.0) == pytest.approx(PAPER_SHAKER.amp_um(x, 6.0), rel=1e-12)


@pytest.mark.parametrize("text, key", [("freq_hz,amp_um\n200,36\n", "freq_hz"),
                                       ("200,36\n150,9\n", "freq_hz/amp_um"),
                                       ("200,36\n300,abc\n", "line 2"),
                                       ("200\n300,9\n", "line 1")])
def test_bad_tables_name_the_problem(tmp_path, text, key):
    f = tmp_path / "bad.csv"
    f.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as e:
        load_tray_law(str(f))
    assert e.value.key == key
    with pytest.raises(InputError) as e:
        load_tray_law(str(tmp_path / "missing.csv"))
    with pytest.raises(InputError, match="outside the table"):
        TableLaw((200.0, 400.0), (36.0, 9.0)).amp_um(500.0)


def test_a_scenario_runs_on_the_file_law_and_records_it(tmp_path):
    f = tmp_path / "t.csv"
    f.write_text("freq_hz,amp_um\n200,3\n300,1\n", encoding="utf-8")
    law = load_tray_law(str(f))
    r = run_scenario("paper-ablations", quick=True, out_dir=None, tray_law=law, quiet=True)
    assert r.numbers["tray_law"]["source"] == str(f)
    assert r.numbers["amp_um"] == pytest.approx(law.amp_um(240.0, 4.0))
    d = run_scenario("paper-ablations", quick=True, out_dir=None, quiet=True)
    assert d.numbers["tray_law"]["law"].startswith("constant drive") and d.numbers["amp_um"] != r.numbers["amp_um"]
