"""The kiosk: a whole simulated world in three files (this one, kiosk.domain.yaml, kiosk.study.yaml).

A robot at a counter greets customers. A customer arrives now and then and waits (up to their
patience); a person detector looks every few seconds, missing customers and seeing passers-by.
The world, its scenarios, its behaviour tree, its demo and its study plug into pearl_sim's frame;
it registers by the entry point ``pearl.worlds: kiosk = kiosk_world:WORLD`` as any world outside
the repository would.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional

from pearl_sim.messages import Message, StepResult
from pearl_sim.world_base import StudyWorld
from pearl_sim.world_demo import WorldDemo
from pearl_sim.world_scenario import Checker, load_episodes, read_seed_and_steps
from pearl_sim.world_study import StandardStudy
from pearl_sim.world_tree import TreeDecider, branch
from pearl_sim.worlds import SimWorld

HERE = Path(__file__).resolve().parent
LOOK_EVERY = 3.0          # s between two looks of the detector


@dataclass
class KioskScenario:
    """One episode of the kiosk."""

    name: str
    seed: int
    max_steps: int
    arrival_every: float
    detector_miss: float
    false_alarm: float
    patience: float
    step_timeout: float
    word_error_rate: float = 0.0     # no speech here; the frame's noise axis leaves the detector alone

    def tracker_parameters(self) -> Dict[str, Any]:
        return {"step_timeout": self.step_timeout, "timeout_observation": "nobody"}


def load_kiosk_scenarios(path) -> List[KioskScenario]:
    """The episodes of a kiosk scenario file (errors name the file and field)."""
    def episode(data: dict, source: str, prefix: str) -> KioskScenario:
        c = Checker(source)
        seed, steps = read_seed_and_steps(c, data, prefix, 40, 1000)
        return KioskScenario(name=str(data.get("name", Path(source).stem)), seed=seed, max_steps=steps,
                             arrival_every=c.number(data, "arrival_every", prefix, 40.0, 1.0, 1e4, "s"),
                             detector_miss=c.number(data, "detector_miss", prefix, 0.2, 0.0, 1.0),
                             false_alarm=c.number(data, "false_alarm", prefix, 0.05, 0.0, 1.0),
                             patience=c.number(data, "patience", prefix, 60.0, 1.0, 1e4, "s"),
                             step_timeout=c.number(data, "step_timeout", prefix, 5.0, 0.5, 60.0, "s"))
    return load_episodes(path, "kiosk", episode)


@dataclass
class KioskMetrics:
    customers: int = 0
    served: int = 0
    left: int = 0
    wrong_actions: int = 0
    wrong: List[str] = field(default_factory=list)


class KioskWorld(StudyWorld):
    """Ground truth of one kiosk episode."""

    def __init__(self, scenario: KioskScenario, seed: Optional[int] = None, word_error_rate: Optional[float] = None):
        super().__init__(scenario, seed, word_error_rate, "counter")
        self.metrics = KioskMetrics()
        self.waiting_since: Optional[float] = None
        self.next_arrival = self._draw_arrival()
        self.next_look = LOOK_EVERY

    def _draw_arrival(self) -> float:
        return self.time + float(self.rng.exponential(self.scenario.arrival_every))

    def truth(self) -> Dict[str, str]:
        return {"Customer": "waiting" if self.waiting_since is not None else "none"}

    def _idle(self, seconds: float, events: List[str]) -> None:
        end = self.time + seconds
        while self.time < end - 1e-9:
            due = self.next_arrival if self.waiting_since is None else self.waiting_since + self.scenario.patience
            self.time = max(self.time, min(end, due, self.next_look))
            if self.waiting_since is None and self.time >= self.next_arrival:
                self.waiting_since = self.time
                self.metrics.customers += 1
                events.append("a customer comes to the counter")
            if self.waiting_since is not None and self.time - self.waiting_since >= self.scenario.patience:
                self.waiting_since, self.next_arrival = None, self._draw_arrival()
                self.metrics.left += 1
                events.append("a customer leaves unserved")
            if self.time >= self.next_look:
                self.next_look += LOOK_EVERY
                seen = (self.rng.random() >= self.scenario.detector_miss if self.waiting_since is not None
                        else self.rng.random() < self.scenario.false_alarm)
                if seen:
                    self._pending.append(Message(self.time, "Presence", "person_seen"))

    def act(self, action: str) -> StepResult:
        start, events, wrong = self.time, [], None
        if action == "Greet":
            self._idle(2.0, events)                 # "Hello! How can I help?"
            if self.waiting_since is None:
                wrong = "greeted nobody"
            else:
                self.waiting_since, self.next_arrival = None, self._draw_arrival()
                self.metrics.served += 1
                events.append("a customer is served")
        return self._close(action, start, events, wrong)


class KioskTree(TreeDecider):
    """The kiosk's behaviour tree: greet when the detector saw somebody on the last step, else wait."""

    def __init__(self, actions: List[str]):
        def build(ns: str):
            import py_trees

            return py_trees.composites.Selector("Kiosk", memory=False, children=[
                branch("Greet", ns, ("seen", "action"), lambda bb: bb.seen, "Greet")])
        super().__init__("behaviour_tree", actions, "/kiosk", ("seen", "action"), build)

    def reset(self) -> None:
        self.blackboard.seen = False

    def observe(self, action: str, observation: str) -> None:
        self.blackboard.seen = observation == "person_seen"


def _metrics(world: KioskWorld) -> Dict[str, Any]:
    m = world.metrics
    return {"customers": m.customers, "served": m.served, "left": m.left, "wrong_actions": m.wrong_actions}


DEMO = WorldDemo(load_scenarios=load_kiosk_scenarios, make_world=lambda sc, seed, domain: KioskWorld(sc, seed=seed),
                 metrics=_metrics,
                 outcome=lambda m: f"outcome: {m['served']}/{m['customers']} customer(s) served, {m['left']} left, "
                                   f"{m['wrong_actions']} wrong action(s)")
STUDY = StandardStudy(make_world=lambda sc, seed, wer: KioskWorld(sc, seed=seed, word_error_rate=wer),
                      score=lambda w: {"success": w.metrics.left == 0, "served": w.metrics.served,
                                       "left": w.metrics.left},
                      tree=KioskTree)
EXPERIMENT = STUDY.experiment(load_kiosk_scenarios, default_noise="0", default_seeds=3)
WORLD = SimWorld("kiosk", "a kiosk robot greeting customers (three files)", "kiosk.study.yaml", "kiosk.study.yaml",
                 params_file="", demo="kiosk_world:DEMO", experiment="kiosk_world:EXPERIMENT", root=str(HERE))
