"""The step rules' settings: :class:`StepSettings`, the one source of the belief tracker's parameters.

Each field is a ``belief_tracker`` node parameter with its default, range, description and whether it
may change while running (:meth:`StepSettings.parameters`); :func:`drive_actions` says which actions
are drives. :class:`~pearl_pomdp.tracking.BeliefTracker` runs the step protocol with them.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from pearl_pomdp.navigation import DriveTimer, places_from_parameters

__all__ = ["StepSettings", "SettingSpec", "drive_actions"]


def drive_actions(domain, category: str) -> List[str]:
    """The actions of ``domain`` tagged ``category: <category>`` (drives: never timed out);
    none for an empty ``category``."""
    return domain.actions_in(category) if category else []


def _setting(default: Any, description: str, *, range: Optional[Tuple[float, float]] = None,
             live: bool = False, parameter: bool = True) -> Any:
    """A :class:`StepSettings` field: its default and what the node's parameter table says of it."""
    return field(default=default, metadata={"description": description, "range": range, "live": live,
                                            "parameter": parameter})


@dataclass(frozen=True)
class SettingSpec:
    """One :class:`StepSettings` field as a node parameter (see :meth:`StepSettings.parameters`).

    Attributes:
        name: the field and parameter name.
        default: the default as a parameter value (tuples as lists, ``None`` as ``[]``).
        description: one line for ``ros2 param describe`` (the reason for the default included).
        range: ``(low, high)`` for numbers (checked by :class:`StepSettings` and by rclpy).
        live: True when it may change at run time (:meth:`BeliefTracker.set_live`).
    """

    name: str
    default: Any
    description: str
    range: Optional[Tuple[float, float]] = None
    live: bool = False


@dataclass(frozen=True)
class StepSettings:
    """The step rules' parameters: the one source of their defaults, ranges and descriptions.

    The ``belief_tracker`` node's parameter table is generated from these fields
    (:meth:`parameters`); ``config/pearl_nodes.yaml`` holds only the values the shipped robot
    sets differently, each with its reason. Every field is checked here (a value out of its
    range raises ``ValueError`` naming the field).

    ``places``: ``(name, x, y)`` of each place, metres in the map frame — not a parameter of
    its own: the params file's ``location_names`` / ``locations.<name>`` (:meth:`from_params`).
    """

    step_timeout: float = _setting(
        10.0, "Seconds without input after an action before the step is closed with timeout_observation "
              "(0: wait forever): a resident answering a question takes a few seconds; 10 s of silence is "
              "no answer", range=(0.0, 3600.0), live=True)
    timeout_observation: str = _setting(
        "", "Observation symbol that closes a step on timeout; empty: the domain's silence symbol (the one an "
            "input declares as silence:, else a speech input's unknown symbol: silence is taken as unrecognised "
            "speech)")
    no_timeout_actions: Optional[Tuple[str, ...]] = _setting(
        None, "Actions whose step only an input closes (drives end with a landmark); empty: the domain's "
              "actions of drive_category; names the model does not have are ignored")
    drive_category: str = _setting(
        "", "Action category (the domain's category:) whose actions are drives when no_timeout_actions is "
            "empty; empty: no category, a domain's drives are named in no_timeout_actions")
    max_pending: int = _setting(
        8, "Observations that may wait for the next action (FIFO): a burst longer than this is a fault",
        range=(0, 1000))
    stale_after: float = _setting(
        0.0, "Drop a waiting observation older than this many seconds when it would be used (0: never)",
        range=(0.0, 3600.0), live=True)
    confidence_floor: float = _setting(
        0.0, "Speech recognised with a lower confidence counts as unknown (0: every keyword counts)",
        range=(0.0, 1.0), live=True)
    drive_speed: float = _setting(
        0.0, "Drives get a deadline from distance at this speed (m/s) and are closed with "
             "nav_failed_observation when it passes (0: no drive deadline; needs location_names)",
        range=(0.0, 5.0))
    guide_speed: float = _setting(
        0.03, "Speed (m/s) guide_actions are timed at: the slowest pace, rests included, of a resident "
              "the robot still guides (a 5 cm/s walker who rests 10 s every ~25 s averages 0.035 m/s)",
        range=(0.005, 3.0))
    guide_actions: Tuple[str, ...] = _setting((), "Drives that walk the resident along (timed at guide_speed)")
    drive_path_factor: float = _setting(
        1.4, "Path length over straight-line distance: corridors and doors make paths ~40 % longer",
        range=(1.0, 10.0))
    drive_slack: float = _setting(
        1.5, "Multiplier on a drive's expected time: people in the way, the navigation's recoveries",
        range=(1.0, 10.0))
    drive_margin: float = _setting(
        10.0, "Seconds added to every drive's deadline: turning on the spot, a door, start-up",
        range=(0.0, 3600.0))
    drive_max_seconds: float = _setting(
        1800.0, "No drive deadline is longer than this (s): no drive waits longer than half an hour",
        range=(1.0, 86400.0))
    nav_failed_observation: str = _setting(
        "", "Observation symbol of the domain that closes a drive at its deadline (needed when drive_speed > 0)")
    place_feature: str = _setting(
        "", "State feature whose values are the places the drives go to (needed when drive_speed > 0)")
    places: Tuple[Tuple[str, float, float], ...] = _setting((), "", parameter=False)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            lo_hi = f.metadata.get("range")
            if lo_hi is None:
                continue
            value = getattr(self, f.name)
            lo, hi = lo_hi
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or not lo <= value <= hi:
                raise ValueError(f"{f.name} must be in [{lo:g}, {hi:g}], got {value!r}")

    @classmethod
    def parameters(cls) -> List[SettingSpec]:
        """The fields that are node parameters, in order, as the node declares them."""
        out = []
        for f in dataclasses.fields(cls):
            if not f.metadata.get("parameter", False):
                continue
            default = f.default
            if default is None or isinstance(default, tuple):
                default = list(default or ())
            out.append(SettingSpec(f.name, default, f.metadata["description"], f.metadata["range"],
                                   f.metadata["live"]))
        return out

    @classmethod
    def live_names(cls) -> Tuple[str, ...]:
        """The fields that may change at run time (:meth:`BeliefTracker.set_live`)."""
        return tuple(s.name for s in cls.parameters() if s.live)

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> "StepSettings":
        """From a parameter table (the node's, or the params file's belief_tracker and ``/**`` sections).

        String lists may hold ``""`` entries (ROS has no typed empty list in a params file):
        they are dropped, and an empty ``no_timeout_actions`` means "the domain's drives".
        The places are ``location_names`` with ``locations.<name>`` = ``[x, y, yaw]``
        (:func:`~pearl_pomdp.navigation.places_from_parameters`, the one place parser).

        Raises:
            ValueError: a value is out of range or a place's pose is malformed (names the parameter).
        """
        names = {f.name for f in dataclasses.fields(cls)}
        kwargs: Dict[str, Any] = {k: v for k, v in params.items() if k in names}
        if "no_timeout_actions" in kwargs:
            given = tuple(a for a in (kwargs["no_timeout_actions"] or ()) if a)
            kwargs["no_timeout_actions"] = given or None
        if "guide_actions" in kwargs:
            kwargs["guide_actions"] = tuple(a for a in kwargs["guide_actions"] if a)
        place_names = [n for n in params.get("location_names", ()) if n]
        if place_names and "places" not in params:
            poses = {name: params.get(f"locations.{name}", ()) for name in place_names}
            kwargs["places"] = tuple((p.name, p.x, p.y) for p in places_from_parameters(place_names, poses).values())
        return cls(**kwargs)

    def drive_timer(self, domain, drives: Sequence[str]) -> Optional[DriveTimer]:
        """The :class:`~pearl_pomdp.navigation.DriveTimer` of these settings, or ``None`` (off,
        no domain, or no drive with a place goal).

        Raises:
            ValueError: a field is out of range or a drive's goal has no pose (names the parameter).
        """
        if self.drive_speed <= 0 or domain is None:
            return None
        from pearl_pomdp.navigation import DriveDeadline, Place

        for name in ("nav_failed_observation", "place_feature"):
            if not getattr(self, name):
                raise ValueError(f"{name}: drive deadlines (drive_speed > 0) need it (the domain's "
                                 + ("symbol that closes a drive at its deadline)" if name == "nav_failed_observation"
                                    else "state feature whose values are the drives' places)"))
        deadline = DriveDeadline(speed=self.drive_speed, path_factor=self.drive_path_factor, slack=self.drive_slack,
                                 margin=self.drive_margin, max_seconds=self.drive_max_seconds)
        places = {name: Place(name, x, y) for name, x, y in self.places}
        if not places:
            raise ValueError("location_names: drive deadlines (drive_speed > 0) need the places' poses "
                             "(location_names and locations.<name>)")
        return DriveTimer.for_domain(domain, drives, places, deadline, self.place_feature, self.guide_actions,
                                     self.guide_speed)
