"""Navigation facts the manager needs, without ROS: places, landmarks, drive deadlines.

* :class:`Place` — a named pose in the map frame (``config/pearl_nodes.yaml`` ``locations``).
* :class:`LandmarkDetector` — the pose → Laser landmark path. The robot's localised
  position (``/amcl_pose`` or ``/odom`` on a robot, the simulated base in the sim) is fed
  one sample at a time; a landmark's symbol (``atPhysio``) is reported **once** when the
  robot comes within ``entry_radius`` of its place, and the place counts as left only
  beyond ``exit_radius`` (> ``entry_radius``). Jitter of the position around the entry
  circle therefore reports nothing more: hysteresis of ``exit_radius − entry_radius``.
* :class:`DriveDeadline` — how long a drive may take before the manager calls it failed:
  ``margin + slack · path_factor · distance / speed``, capped at ``max_seconds``.
* :class:`DriveTimer` — the deadline of each of a domain's drives (the actions of the
  tracker's ``drive_category``; Pearl's are ``category: Move``): from the place the robot
  most likely is to the place the drive sets. The belief tracker (:mod:`pearl_pomdp.tracking`)
  closes a drive that misses it with its ``nav_failed_observation`` (Pearl's ``navFailed``)
  — on the robot, in the demo and in the study alike.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

__all__ = ["Place", "Landmark", "LandmarkDetector", "DriveDeadline", "DriveTimer", "places_from_parameters"]


@dataclass(frozen=True)
class Place:
    """A named pose: ``x``, ``y`` in metres and ``yaw`` in radians, in the map frame."""

    name: str
    x: float
    y: float
    yaw: float = 0.0

    def distance_to(self, x: float, y: float) -> float:
        """Straight-line distance (m) from ``(x, y)`` to this place."""
        return math.hypot(x - self.x, y - self.y)


@dataclass(frozen=True)
class Landmark:
    """A place whose arrival is an observation.

    Attributes:
        place: where.
        symbol: the observation reported on arrival (a Laser symbol of the domain, ``atPhysio``).
        entry_radius: metres from the place within which the robot has arrived (> 0).
        exit_radius: metres beyond which it has left again (> ``entry_radius``).
    """

    place: Place
    symbol: str
    entry_radius: float
    exit_radius: float

    def __post_init__(self):
        if not self.symbol:
            raise ValueError(f"landmark {self.place.name}: empty symbol")
        if not (math.isfinite(self.entry_radius) and self.entry_radius > 0):
            raise ValueError(f"landmark {self.place.name}: entry_radius must be > 0 m, got {self.entry_radius}")
        if not (math.isfinite(self.exit_radius) and self.exit_radius > self.entry_radius):
            raise ValueError(f"landmark {self.place.name}: exit_radius must be > entry_radius "
                             f"({self.entry_radius} m), got {self.exit_radius}")


@dataclass
class LandmarkDetector:
    """Reports a landmark's symbol once per arrival (see the module doc).

    Args:
        landmarks: the landmarks (names unique).
        report_initial: whether a landmark the *first* position is already inside is
            reported. Default False: a robot that starts on its dock has not *arrived* at
            home, and an observation nobody asked for would close the manager's first step.

    Attributes:
        inside: names of the places the robot is in now.
        reported: per symbol, how many arrivals were reported.
    """

    landmarks: Sequence[Landmark]
    report_initial: bool = False
    inside: set = field(default_factory=set, init=False)
    reported: Dict[str, int] = field(default_factory=dict, init=False)
    _started: bool = field(default=False, init=False, repr=False)

    def __post_init__(self):
        names = [lm.place.name for lm in self.landmarks]
        duplicate = sorted({n for n in names if names.count(n) > 1})
        if duplicate:
            raise ValueError(f"landmarks: place {duplicate[0]!r} given twice")

    def update(self, x: float, y: float) -> List[str]:
        """Feed one position (map frame, m); returns the symbols of the places just entered.

        A non-finite position is ignored (returns ``[]``; the state is kept).
        """
        if not (math.isfinite(x) and math.isfinite(y)):
            return []
        entered: List[str] = []
        first = not self._started
        self._started = True
        for lm in self.landmarks:
            d = lm.place.distance_to(x, y)
            name = lm.place.name
            if name in self.inside:
                if d > lm.exit_radius:
                    self.inside.discard(name)
            elif d <= lm.entry_radius:
                self.inside.add(name)
                if not first or self.report_initial:
                    entered.append(lm.symbol)
                    self.reported[lm.symbol] = self.reported.get(lm.symbol, 0) + 1
        return entered

    def reset(self) -> None:
        """Forget where the robot is (e.g. after re-localisation): the next position starts afresh."""
        self.inside.clear()
        self._started = False


@dataclass(frozen=True)
class DriveDeadline:
    """How long a drive may take: ``min(max_seconds, margin + slack · path_factor · distance / speed)``.

    Attributes:
        speed: expected speed in m/s (> 0): the robot's cruise speed for a drive, the slowest
            resident's pace the manager still guides for a guidance.
        path_factor: path length over straight-line distance (≥ 1; corridors and doors).
        slack: multiplier on the expected time (≥ 1; people in the way, slow-downs).
        margin: seconds added to every drive (≥ 0; start-up, turning in place, a door).
        max_seconds: upper bound (> 0): no drive waits longer than this.

    Raises:
        ValueError: a field is out of range (the message names it and the value).
    """

    speed: float = 0.6
    path_factor: float = 1.4
    slack: float = 1.5
    margin: float = 10.0
    max_seconds: float = 900.0

    def __post_init__(self):
        checks = (("speed", self.speed > 0, "> 0 m/s"), ("path_factor", self.path_factor >= 1, ">= 1"),
                  ("slack", self.slack >= 1, ">= 1"), ("margin", self.margin >= 0, ">= 0 s"),
                  ("max_seconds", self.max_seconds > 0, "> 0 s"))
        for name, ok, want in checks:
            value = getattr(self, name)
            if not (math.isfinite(value) and ok):
                raise ValueError(f"DriveDeadline.{name} must be {want}, got {value}")

    def seconds(self, distance: float, speed: Optional[float] = None) -> float:
        """Seconds allowed for ``distance`` metres (straight line) at ``speed`` (default :attr:`speed`).

        Raises:
            ValueError: ``distance`` < 0 or not finite, or ``speed`` ≤ 0.
        """
        if not (math.isfinite(distance) and distance >= 0):
            raise ValueError(f"drive distance must be a finite number >= 0 m, got {distance}")
        v = self.speed if speed is None else speed
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"drive speed must be > 0 m/s, got {v}")
        return min(self.max_seconds, self.margin + self.slack * self.path_factor * distance / v)

    def between(self, start: Place, goal: Place, speed: Optional[float] = None) -> float:
        """Seconds allowed to drive from ``start`` to ``goal`` (straight-line distance × factors)."""
        return self.seconds(start.distance_to(goal.x, goal.y), speed)


@dataclass(frozen=True)
class DriveTimer:
    """Seconds each drive may take: :class:`DriveDeadline` over the distance from origin to goal.

    Attributes:
        goals: drive action → the place it drives to.
        places: place name → :class:`Place` (the map).
        deadline: the time rule.
        guide_actions: drives that walk a resident along; they are timed at ``guide_speed``.
        guide_speed: m/s, the slowest pace (rests included) the manager still guides.
    """

    goals: Dict[str, str]
    places: Dict[str, Place]
    deadline: DriveDeadline = DriveDeadline()
    guide_actions: Tuple[str, ...] = ()
    guide_speed: float = 0.03

    def __post_init__(self):
        missing = sorted({g for g in self.goals.values() if g not in self.places})
        if missing:
            drive = next(a for a, g in self.goals.items() if g == missing[0])
            raise ValueError(f"location_names: drive {drive} goes to {missing[0]!r}, which has no pose "
                             f"(places: {', '.join(self.places) or 'none'})")
        if not (math.isfinite(self.guide_speed) and self.guide_speed > 0):
            raise ValueError(f"guide_speed must be > 0 m/s, got {self.guide_speed}")

    @classmethod
    def for_domain(cls, domain, drives: Iterable[str], places: Dict[str, Place], deadline: DriveDeadline,
                   place_feature: str, guide_actions: Iterable[str] = (),
                   guide_speed: float = 0.03) -> Optional["DriveTimer"]:
        """The timer of ``drives`` in ``domain``: each one's goal is the value it (most likely) sets
        on ``place_feature``. Drives without such a value are left out (never timed);
        ``None`` when no drive is left.

        Raises:
            ValueError: ``place_feature`` is not a feature of the domain, or a goal has no pose.
        """
        if place_feature not in domain.feature_names:
            raise ValueError(f"place_feature {place_feature!r} is not a feature of {domain.name} "
                             f"(features: {', '.join(domain.feature_names)})")
        goals = {a: g for a in drives if (g := domain.intended_effect(a, place_feature)) is not None}
        if not goals:
            return None
        return cls(goals, dict(places), deadline, tuple(a for a in guide_actions if a), float(guide_speed))

    def seconds(self, action: str, origin: Optional[str] = None) -> Optional[float]:
        """Seconds allowed for ``action`` started at place ``origin``; ``None`` if it is not a timed drive.

        An unknown ``origin`` (``None`` or not a place) is taken as the farthest place from the goal.
        """
        goal_name = self.goals.get(action)
        if goal_name is None:
            return None
        goal = self.places[goal_name]
        if origin in self.places:
            distance = self.places[origin].distance_to(goal.x, goal.y)
        else:
            distance = max(p.distance_to(goal.x, goal.y) for p in self.places.values())
        speed = self.guide_speed if action in self.guide_actions else None
        return self.deadline.seconds(distance, speed)

    def remaining_seconds(self, action: str, path_remaining: float) -> Optional[float]:
        """Seconds allowed for the ``path_remaining`` metres a running drive ``action`` still has
        along its planned path (Nav2's feedback: a path length, so no ``path_factor``), at its speed
        (``guide_speed`` for a guidance), with the rule's slack and margin, capped at ``max_seconds``;
        ``None`` if ``action`` is not a timed drive.

        Raises:
            ValueError: ``path_remaining`` < 0 or not finite.
        """
        if action not in self.goals:
            return None
        if not (math.isfinite(path_remaining) and path_remaining >= 0):
            raise ValueError(f"distance remaining must be a finite number >= 0 m, got {path_remaining}")
        rule = self.deadline
        speed = self.guide_speed if action in self.guide_actions else rule.speed
        return min(rule.max_seconds, rule.margin + rule.slack * path_remaining / speed)


def places_from_parameters(names: Iterable[str], poses: Mapping[str, Sequence[float]]) -> Dict[str, Place]:
    """``{name: Place}`` from ``location_names`` and ``locations.<name>`` = [x, y, yaw].

    Raises:
        ValueError: a pose is missing, not three finite numbers (the message names the place).
    """
    out: Dict[str, Place] = {}
    for name in names:
        pose: Tuple[float, ...] = tuple(float(v) for v in poses.get(name, ()))
        if len(pose) != 3 or not all(math.isfinite(v) for v in pose):
            raise ValueError(f"locations.{name}: expected [x, y, yaw] (finite numbers), got {list(pose)}")
        out[name] = Place(name, *pose)
    return out
