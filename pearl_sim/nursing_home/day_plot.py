"""A working day at a glance: where she is, where the robot is, its battery, and what it did.

:func:`plot_day` draws one PNG from :func:`pearl_sim.nursing_home.day_study.run_day`'s ``timeline``
(one row per action: time, action, the robot's place, her state, the battery) and the day's
checklist: four lanes over the clock from 08:00 to 20:00.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, Sequence

from pearl_sim.nursing_home.day import DAY_SECONDS, DAY_START

__all__ = ["plot_day", "RESIDENT_COLOURS", "ROBOT_PLACES"]

#: Her states in the timeline and their colours (away from her room in warm colours).
RESIDENT_COLOURS = {"room": "#9ecae1", "asleep": "#3182bd", "breakfast": "#fdae6b", "lunch": "#fdae6b",
                    "supper": "#fdae6b", "lounge": "#fd8d3c", "corridor": "#c7e9c0",
                    "walking with the robot": "#31a354", "physio": "#74c476", "therapy": "#006d2c"}
#: The robot's places, bottom to top.
ROBOT_PLACES = ("home", "room", "physio")
#: Actions marked on the action lane, by kind.
ACTION_KINDS = {"Remind": ("RemindPhysioAppt", "RemindVitamin", "UpdateChecklist"),
                "Tell": ("TellTime", "TellWeather"),
                "Guide": ("GuideToPhysio", "TerminateGuidance"),
                "Ask": ("ConfirmGuideToPhysio", "VerifyInfoRequest", "ConfirmWantTime", "ConfirmWantWeather",
                        "ConfirmGoHome", "ConfirmDone", "CheckUserPresent"),
                "Ring": ("RingDoorBell",), "Dock": ("RechargeBattery",),
                "Drive": ("GotoPatientRoom", "GoHome")}


def _hours(t: float) -> float:
    return (DAY_START + t) / 3600.0


def _spans(rows: Sequence[Dict[str, Any]], key: str) -> List[tuple]:
    """``(start, end, value)`` runs of ``key`` over the timeline (the last run ends at 20:00)."""
    spans: List[tuple] = []
    for row in rows:
        if spans and spans[-1][2] == row[key]:
            continue
        if spans:
            spans[-1] = (spans[-1][0], row["t"], spans[-1][2])
        spans.append((row["t"], DAY_SECONDS, row[key]))
    return spans


def plot_day(timeline: Sequence[Dict[str, Any]], checklist: Dict[str, Any], path, title: str = "") -> Path:
    """Write the day's picture to ``path`` (PNG) and return it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (her, robot, battery, acts) = plt.subplots(4, 1, figsize=(13, 6.5), sharex=True,
                                                    gridspec_kw={"height_ratios": [1, 1.4, 1.2, 1.4]})
    for start, end, state in _spans(timeline, "resident"):
        her.axvspan(_hours(start), _hours(end), color=RESIDENT_COLOURS.get(state, "#dddddd"), lw=0)
        if end - start > 1500:
            her.text((_hours(start) + _hours(end)) / 2, 0.5, state, ha="center", va="center", fontsize=7)
    her.set_yticks([])
    her.set_ylabel("resident", rotation=0, ha="right", va="center")
    xs, ys = [], []
    for row in timeline:
        xs.append(_hours(row["t"]))
        ys.append(ROBOT_PLACES.index(row["robot"]) if row["robot"] in ROBOT_PLACES else -1)
    robot.step(xs + [_hours(DAY_SECONDS)], ys + ys[-1:], where="post", color="#444444")
    robot.set_yticks(range(len(ROBOT_PLACES)), ROBOT_PLACES)
    robot.set_ylim(-0.5, len(ROBOT_PLACES) - 0.5)
    robot.set_ylabel("robot", rotation=0, ha="right", va="center")
    battery.plot(xs, [row["battery"] * 100 for row in timeline], color="#e6550d")
    battery.axhline(20, color="#e6550d", ls=":", lw=0.8)
    battery.set_ylim(0, 105)
    battery.set_ylabel("battery %", rotation=0, ha="right", va="center")
    for lane, (kind, names) in enumerate(ACTION_KINDS.items()):
        ts = [_hours(row["t"]) for row in timeline if row["action"] in names]
        acts.scatter(ts, [lane] * len(ts), marker="|", s=120, label=kind)
    acts.set_yticks(range(len(ACTION_KINDS)), list(ACTION_KINDS))
    acts.set_ylim(-0.7, len(ACTION_KINDS) - 0.3)
    acts.set_xlim(_hours(0), _hours(DAY_SECONDS))
    acts.set_xticks(range(8, 21), [f"{h:02d}:00" for h in range(8, 21)])
    c = checklist
    summary = (f"reminders on time {c['reminders_on_time']}/{c['reminders_due']} · walks {c['walks_completed']}/"
               f"{c['walks_wanted']} · questions {c['questions_answered']}/{c['questions_raised']} · "
               f"unprompted {c['unprompted']} · wrong {c['wrong_actions']} · "
               f"{'battery EMPTY' if c['battery_empty'] else 'battery never empty'} · "
               f"{'docked' if c['docked_at_end'] else 'NOT docked'} at 20:00 · station {c['station_share']:.0%} of idle time")
    fig.suptitle((title + "\n" if title else "") + summary, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
