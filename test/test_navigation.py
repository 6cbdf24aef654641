"""The ROS-free navigation core: landmark hysteresis and drive deadlines.

The pose streams are generated with a seed: a drive from the resident's room to the
physiotherapy entrance sampled at 10 Hz with AMCL-like jitter, which ends by creeping
along the entry circle (the robot stops 1 m from the goal while localisation jitters by
±15 cm): the entry circle is crossed dozens of times, and ``atPhysio`` is reported once.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from pearl_pomdp.navigation import DriveDeadline, Landmark, LandmarkDetector, Place, places_from_parameters

HOME, ROOM, PHYSIO = Place("home", 0.0, 0.0), Place("room", 8.0, 3.5, 1.5708), Place("physio", 21.0, -4.0, 3.1416)


def detector(entry=1.0, exit_=2.0, **kw):
    return LandmarkDetector([Landmark(HOME, "atHome", entry, exit_), Landmark(ROOM, "atRoom", entry, exit_),
                             Landmark(PHYSIO, "atPhysio", entry, exit_)], **kw)


def drive(start, goal, stop_short, rng, jitter=0.05, hz=10.0, speed=0.6, dwell_s=60.0, dwell_jitter=0.15):
    """Positions from ``start`` to ``stop_short`` m before ``goal``, then a dwell there (jittered)."""
    d = start.distance_to(goal.x, goal.y)
    ux, uy = (goal.x - start.x) / d, (goal.y - start.y) / d
    path = np.arange(0.0, d - stop_short, speed / hz)
    out = [(start.x + ux * s + rng.normal(0, jitter), start.y + uy * s + rng.normal(0, jitter)) for s in path]
    end = (goal.x - ux * stop_short, goal.y - uy * stop_short)
    out += [(end[0] + rng.normal(0, dwell_jitter), end[1] + rng.normal(0, dwell_jitter))
            for _ in range(int(dwell_s * hz))]
    return out


def crossings(points, place, radius):
    inside = [place.distance_to(x, y) <= radius for x, y in points]
    return sum(1 for a, b in zip(inside, inside[1:]) if a != b)


@pytest.mark.parametrize("seed", range(5))
def test_entering_physio_with_jitter_at_the_boundary_reports_atphysio_once(seed):
    rng = np.random.default_rng(seed)
    points = drive(ROOM, PHYSIO, stop_short=1.0, rng=rng)  # stops ON the entry circle
    assert crossings(points, PHYSIO, 1.0) >= 20  # the stream really chatters across the entry radius
    det = detector()
    reported = [s for x, y in points for s in det.update(x, y)]
    assert reported == ["atPhysio"]
    assert det.inside == {"physio"}


def test_without_hysteresis_the_same_stream_would_chatter():
    """The same stream with exit radius = entry radius + 1 mm reports many arrivals: the hysteresis is what helps."""
    rng = np.random.default_rng(0)
    points = drive(ROOM, PHYSIO, stop_short=1.0, rng=rng)
    det = detector(1.0, 1.001)
    assert len([s for x, y in points for s in det.update(x, y)]) >= 10


def test_leaving_beyond_the_exit_radius_and_coming_back_reports_again():
    det = detector()
    stream = [(8.0, 3.5), (14.0, 0.0), (20.2, -4.0), (19.5, -4.0), (18.5, -4.0), (20.5, -4.0), (19.1, -4.0),
              (20.9, -4.0)]
    got = [det.update(x, y) for x, y in stream]
    # The first pose (in the room) is the start, not an arrival. 19.5 and 19.1 are 1.5 and 1.9 m
    # out (inside the exit radius: still there); 18.5 is 2.5 m out: left, so 20.5 is a new arrival.
    assert got == [[], [], ["atPhysio"], [], [], ["atPhysio"], [], []]
    assert det.reported == {"atPhysio": 2}


def test_the_first_pose_is_reported_only_when_asked_and_nan_is_ignored():
    assert detector().update(0.1, 0.0) == []
    assert detector(report_initial=True).update(0.1, 0.0) == ["atHome"]
    det = detector()
    assert det.update(float("nan"), 0.0) == [] and det.update(0.0, 0.0) == []  # NaN did not count as the first pose


def test_reset_forgets_the_place():
    det = detector()
    det.update(30.0, 30.0)
    assert det.update(21.0, -4.0) == ["atPhysio"]
    det.reset()
    assert det.update(21.0, -4.0) == [] and det.inside == {"physio"}


@pytest.mark.parametrize("entry, exit_, message", [
    (0.0, 1.0, "landmark physio: entry_radius must be > 0 m, got 0.0"),
    (1.0, 1.0, "landmark physio: exit_radius must be > entry_radius (1.0 m), got 1.0"),
    (1.0, float("nan"), "landmark physio: exit_radius must be > entry_radius (1.0 m), got nan"),
])
def test_bad_radii_name_the_landmark(entry, exit_, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        Landmark(PHYSIO, "atPhysio", entry, exit_)


def test_duplicate_places_are_refused():
    with pytest.raises(ValueError, match="place 'home' given twice"):
        LandmarkDetector([Landmark(HOME, "atHome", 1, 2), Landmark(HOME, "atDock", 1, 2)])


def test_places_from_parameters():
    places = places_from_parameters(["home", "physio"], {"home": [0, 0, 0], "physio": [21.0, -4.0, 3.1416]})
    assert places["physio"] == PHYSIO
    with pytest.raises(ValueError, match=r"^locations.room: expected \[x, y, yaw\] \(finite numbers\), got \[1.0\]$"):
        places_from_parameters(["room"], {"room": [1.0]})


# ------------------------------------------------------------------ drive deadlines
def test_deadline_formula_by_hand():
    dl = DriveDeadline(speed=0.6, path_factor=1.4, slack=1.5, margin=10.0, max_seconds=900.0)
    # room → physio: hypot(13, 7.5) = 15.0083 m; 10 + 1.5 · 1.4 · 15.0083 / 0.6 = 62.529 s
    assert dl.between(ROOM, PHYSIO) == pytest.approx(10 + 1.5 * 1.4 * math.hypot(13.0, 7.5) / 0.6)
    assert dl.between(ROOM, PHYSIO) == pytest.approx(62.529, abs=1e-3)
    assert dl.seconds(0.0) == 10.0
    # guiding a 5 cm/s resident the same way: the guidance speed, not the cruise speed
    assert dl.between(ROOM, PHYSIO, speed=0.05) == pytest.approx(10 + 2.1 * 15.0083 / 0.05, abs=1e-2)
    assert dl.seconds(1000.0) == 900.0  # capped


@pytest.mark.parametrize("kwargs, message", [
    ({"speed": 0.0}, "DriveDeadline.speed must be > 0 m/s, got 0.0"),
    ({"path_factor": 0.9}, "DriveDeadline.path_factor must be >= 1, got 0.9"),
    ({"slack": float("inf")}, "DriveDeadline.slack must be >= 1, got inf"),
    ({"margin": -1.0}, "DriveDeadline.margin must be >= 0 s, got -1.0"),
    ({"max_seconds": 0.0}, "DriveDeadline.max_seconds must be > 0 s, got 0.0"),
])
def test_deadline_settings_are_validated(kwargs, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        DriveDeadline(**kwargs)


def test_deadline_arguments_are_validated():
    dl = DriveDeadline()
    with pytest.raises(ValueError, match="drive distance must be a finite number >= 0 m, got -1.0"):
        dl.seconds(-1.0)
    with pytest.raises(ValueError, match="drive speed must be > 0 m/s, got 0.0"):
        dl.seconds(5.0, speed=0.0)
