"""Validity flags: where a run leaves the model's assumptions, in the result, the summary,
the command's --json and text, and the sweep's table and file (docs/model.md, "Error
control and validity")."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.files import read_sweep_result
from labkit.sim import RobotParams, Shaker, core, simulate
from labkit.sim.result import SMALL_ANGLE_RAD, validity
from tests.conftest import last_json, run_cli


def test_the_flags_follow_their_definitions_on_hand_made_samples():
    """A body 5 mm long and 2 mm wide, resting gap 50 um: a pitch of 0.02 rad puts its ends
    50 um lower (L/2 x 0.02), a roll of 0.03 its sides 30 um lower (W/2 x 0.03)."""
    p = RobotParams()
    gap = np.array([50.0, 40.0, 3.0, 6000.0])
    ang = np.array([[0.0, 0.0, 0.0], [0.0, 0.03, 0.0], [0.02, 0.0, 0.0], [0.15, 0.0, 0.3]])
    contact = np.array([[2] * 6, [0] * 6, [0] * 6, [0] * 6], np.int8)
    v = validity(p, gap, ang, contact, {"events_lost": 0, "steps_event_capped": 0})
    assert v.max_tilt_rad == 0.15                                   # phi_z (yaw) is no tilt
    assert v.body_edge_gap_um == pytest.approx(min(40.0 - 1000 * 0.03, 3.0 - 2500 * 0.02))   # -47 um
    assert v.body_on_film_feet_up_fraction == 0.25                  # only the 3 um sample: < 5 um, feet up
    assert v.max_jump_um == 6000.0 and v.jump_limit_um == 5000.0
    assert v.flags == ["small_angle", "body_edge_contact", "body_on_film_feet_up", "high_jump"]
    calm = validity(p, gap[:2], ang[:2], contact[:2], {"events_lost": 0, "steps_event_capped": 0})
    assert calm.flags == [] and calm.max_tilt_rad < SMALL_ANGLE_RAD


def test_a_full_event_log_is_flagged_not_silent(monkeypatch):
    monkeypatch.setattr(core, "EVENT_LOG_CAP", 3)
    r = simulate(RobotParams.preset("paper"), Shaker(freq_hz=240.0, amp_um=25.0), duration_s=0.2, seed=0)
    assert len(r.events) == 3 and r.counters["events_lost"] > 0
    assert "event_log_full" in r.validity.flags
    assert r.summary()["validity"]["events_lost"] == r.counters["events_lost"]


def test_the_paper_robot_tumbling_at_240_hz_60_um_is_flagged_in_json_and_text():
    """The calibrated robot at 240 Hz, 60 um tilts to 0.9-1.1 rad in 0.5 s; the run says it left
    the small-angle model. (The issue's case was 600 Hz, 60 um; with the film law finite at
    contact, docs/model.md M7, the robot stays still there, 12 impacts and no tilt in 0.5 s.)
    The tumble is chaotic, but it is no edge case: from a symmetric start and seeds 0, 1, 2 the
    largest tilt was 1.11, 1.00, 0.91 and 0.99 rad, nine times the bound or more (measured)."""
    args = ["simulate", "shaker", "--params", "paper", "--freq-hz", "240", "--amp-um", "60", "--duration-s", "0.5"]
    js = last_json(run_cli(*args, "--json"))
    v = js["validity"]
    assert v["max_tilt_rad"] > SMALL_ANGLE_RAD and "small_angle" in v["flags"]
    assert "LEFT the model's assumptions: small_angle" in run_cli(*args).stdout


def test_a_calm_run_has_no_flags_and_the_sweep_counts_them(tmp_path):
    js = last_json(run_cli("simulate", "shaker", "--params", "published", "--duration-s", "0.2", "--json"))
    assert js["validity"]["flags"] == [] and js["validity"]["max_tilt_rad"] < 1e-3
    out = tmp_path / "s.h5"
    # 600 Hz, 60 um: the robot stands (no flag); 240 Hz, 60 um: it tumbles (the test above)
    sw = last_json(run_cli("simulate", "sweep", "shaker", "--params", "paper", "--freq-hz", "600,240",
                           "--amp-um", "60", "--duration-s", "0.5", "--workers", "1", "--out", str(out), "--json"))
    assert "small_angle" not in sw["points"][0]["flags"] and sw["points"][1]["flags"].get("small_angle") == 1

    back = read_sweep_result(out)
    assert "small_angle" in back.flags[1, 0] and back.summary()["points"][1]["flags"] == sw["points"][1]["flags"]
