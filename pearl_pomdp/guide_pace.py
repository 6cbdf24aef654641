"""Walking-pace adaptation during a guidance, without ROS (the ``guide_pace`` node's core).

The paper's open problem: Pearl drove to physiotherapy at its own speed, and slow residents
were left behind. :class:`GuidePace` turns the navigation's speed into a speed the resident
can follow. Each control step it gets the time step, how far the robot has driven along its
path, the resident's distance behind the robot (``None`` when the people tracker does not
see her) and the navigation's speed, and returns the speed to drive:

* **following** — ``v = clamp(pace + gain · (follow_gap − behind), 0, v_nav)``: her pace
  (an exponential average of her progress, time constant ``pace_time_constant``) plus a
  proportional term that holds her ``follow_gap`` metres behind. A resident faster than the
  robot stays close behind, so the robot drives at the navigation's speed; it never drives
  faster than the navigation asks.
* **waiting** — she fell more than ``stop_gap`` behind, or is not seen: the robot stops,
  and drives on once she is within ``resume_gap`` (< ``stop_gap``: no stop-go chatter).
* **lost** — waiting for longer than ``lost_timeout`` s: :attr:`GuidePace.became_lost` is
  true for that one step (report it once), and the robot keeps waiting; if she catches up
  after all, it follows again.

A resident who stops *close* behind (resting, talking) is not lost: the proportional term
holds the robot ``follow_gap`` ahead of her, at rest, for as long as she stays; she is lost
only when she falls back beyond ``stop_gap`` (turns back, walks elsewhere) or the people
tracker loses her, and does not return within ``lost_timeout``.

Legend: ``behind`` = her distance behind the robot (m); ``progress`` = metres the robot has
driven; her progress = ``progress − behind``; ``pace`` = her estimated speed (m/s).

The simulator (``pearl_sim``) and the ROS node call the same :meth:`GuidePace.step`.
Choose ``lost_timeout`` ≥ (``stop_gap`` − ``resume_gap``) / slowest pace + longest rest:
60 s covers a 5 cm/s resident who also rests 10 s (20 s + 10 s, with margin).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

__all__ = ["GuidePaceConfig", "GuidePace", "FOLLOWING", "WAITING", "LOST"]

FOLLOWING, WAITING, LOST = "following", "waiting", "lost"


@dataclass(frozen=True)
class GuidePaceConfig:
    """Settings of :class:`GuidePace` (see the module doc for the control law).

    Attributes:
        cruise_speed: m/s driven when :meth:`GuidePace.step` is given no navigation speed (> 0).
        follow_gap: m behind the robot at which she is held (> 0).
        resume_gap: m; waiting ends once she is this close (> ``follow_gap``).
        stop_gap: m; following stops when she is farther behind (> ``resume_gap``).
        gain: 1/s; speed per metre she is closer than ``follow_gap`` (> 0).
        pace_time_constant: s; smoothing of her pace estimate (> 0).
        lost_timeout: s of waiting after which she is lost (> 0).

    Raises:
        ValueError: a setting is out of range (the message names it and the value).
    """

    # The one source of these defaults (the guide_pace node declares its parameters from them).
    cruise_speed: float = 0.6          # m/s: Pearl drove at about walking pace
    follow_gap: float = 1.0            # m: she walks one step behind the robot
    resume_gap: float = 1.5            # m: drive on once she is this close again
    stop_gap: float = 2.5              # m: farther behind than this the robot stops and waits (beyond arm's reach)
    gain: float = 0.5
    pace_time_constant: float = 3.0
    lost_timeout: float = 60.0         # s: (stop_gap - resume_gap) / 5 cm/s = 20 s, plus a 10 s rest, doubled

    @classmethod
    def from_params(cls, params, **overrides) -> "GuidePaceConfig":
        """From a parameter table (the ``guide_pace`` section of ``config/pearl_nodes.yaml``);
        keys that are not settings are ignored, ``overrides`` win."""
        names = cls.__dataclass_fields__
        return cls(**{**{k: float(v) for k, v in dict(params).items() if k in names}, **overrides})

    def __post_init__(self):
        for name in ("cruise_speed", "follow_gap", "gain", "pace_time_constant", "lost_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"guide_pace {name} must be > 0, got {value}")
        if not (math.isfinite(self.resume_gap) and self.resume_gap > self.follow_gap):
            raise ValueError(f"guide_pace resume_gap must be > follow_gap ({self.follow_gap} m), got {self.resume_gap}")
        if not (math.isfinite(self.stop_gap) and self.stop_gap > self.resume_gap):
            raise ValueError(f"guide_pace stop_gap must be > resume_gap ({self.resume_gap} m), got {self.stop_gap}")


class GuidePace:
    """The pace filter of one guidance (see the module doc).

    Args:
        config: settings (default :class:`GuidePaceConfig`).

    Attributes:
        state: :data:`FOLLOWING`, :data:`WAITING` or :data:`LOST`.
        pace: her estimated pace (m/s).
        speed: the last commanded speed (m/s).
        waited: seconds waited in the current stop.
        became_lost: true only after the step in which she was declared lost.
        times_lost: how often she was declared lost in this guidance.
        stops: how often the robot stopped to wait in this guidance.
    """

    def __init__(self, config: Optional[GuidePaceConfig] = None):
        self.config = config or GuidePaceConfig()
        self.reset()

    def reset(self) -> None:
        """Start a new guidance: she is beside the robot, pace unknown (0)."""
        self.state = FOLLOWING
        self.pace = 0.0
        self.speed = 0.0
        self.waited = 0.0
        self.became_lost = False
        self.times_lost = 0
        self.stops = 0
        self._her_last: Optional[float] = None

    def step(self, dt: float, robot_progress: float, resident_distance_behind: Optional[float],
             nav_speed: Optional[float] = None) -> float:
        """Advance ``dt`` s; returns the speed (m/s, 0 ≤ v ≤ nav speed) to drive until the next step.

        Args:
            dt: seconds since the previous step (> 0).
            robot_progress: metres the robot has driven along its path since :meth:`reset`.
            resident_distance_behind: her distance behind the robot (m); ``None`` or NaN when
                she is not seen; negative (ahead) counts as 0.
            nav_speed: the navigation's speed now (m/s); ``None``: ``config.cruise_speed``.

        Raises:
            ValueError: ``dt`` ≤ 0 or not finite, or ``robot_progress`` not finite.
        """
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"guide_pace step dt must be > 0 s, got {dt}")
        if not math.isfinite(robot_progress):
            raise ValueError(f"guide_pace robot_progress must be finite, got {robot_progress}")
        c = self.config
        v_max = c.cruise_speed if nav_speed is None else max(0.0, float(nav_speed))
        self.became_lost = False
        raw = resident_distance_behind
        behind = 0.0   # metres she is behind the robot (read only while she is seen)
        if raw is not None and math.isfinite(raw):
            behind = max(0.0, float(raw))
            her = robot_progress - behind
            if self._her_last is not None:
                rate = max(0.0, (her - self._her_last) / dt)
                self.pace += dt / (c.pace_time_constant + dt) * (rate - self.pace)
            self._her_last = her
            if self.state == FOLLOWING and behind > c.stop_gap:
                self._stop()
            elif self.state != FOLLOWING and behind <= c.resume_gap:
                self.state, self.waited = FOLLOWING, 0.0
        else:
            self._her_last = None  # a gap in tracking says nothing about her pace
            if self.state == FOLLOWING:
                self._stop()
        if self.state == FOLLOWING:
            self.speed = min(v_max, max(0.0, self.pace + c.gain * (c.follow_gap - behind)))
        else:
            self.speed = 0.0
            self.waited += dt
            if self.state == WAITING and self.waited >= c.lost_timeout:
                self.state = LOST
                self.became_lost = True
                self.times_lost += 1
        return self.speed

    def _stop(self) -> None:
        self.state, self.waited = WAITING, 0.0
        self.stops += 1
