"""The Pearl task as a ``py_trees`` behaviour tree: the study's main non-POMDP baseline.

This is how a ROS 2 developer would write Pearl's behaviour manager without a POMDP
(py_trees / py_trees_ros is what ROS 2 behaviour managers are built on): a priority
selector over guarded task branches, sequences with memory inside them, retries and
timeouts counted in ticks, a blackboard that holds what was heard, and confirmation
questions when what was heard is ambiguous.

It is an :class:`~pearl_pomdp.interfaces.ObservingDecider` (``reset``, ``observe``,
``execute``) run inside the same core :class:`~pearl_pomdp.executive.Executive` as the
POMDP, so it obeys the same belief-tracker rules (step timeouts → ``unknown``,
queueing, drives that never time out, speech below ``confidence_floor`` → ``unknown``).
It ignores the belief. Each closed step the executive calls :meth:`PearlBehaviourTree.observe`
(the "to blackboard" part, as py_trees_ros subscribers write topics onto the blackboard)
and then :meth:`PearlBehaviourTree.execute`, which ticks the tree and returns the one
primitive action a leaf chose.

Tree (``Pearl`` is a selector without memory: every tick re-checks the guards in
priority order, so a higher branch pre-empts a running lower one)::

    Pearl  (Selector, memory=False)
    ├── End guidance   guiding ∧ at physio              → TerminateGuidance
    ├── Inform         question heard (time / weather)  → TellTime | TellWeather
    ├── Guide          walk requested ∧ contact ∧ room  → Retry×2(GuideToPhysio until atPhysio)
    ├── Remind         reminder pending ∧ no back-off   → Contact → Remind<kind>
    │      Contact (Selector, memory): in contact | TickTimeout 6 (GotoPatientRoom until atRoom,
    │                                               Retry×3(RingDoorBell until answered))
    │      on failure: back off 2 ticks before the next attempt
    ├── Offer walk     walk offer ∧ contact ∧ room      → Retry×2(ConfirmGuideToPhysio) | give up
    ├── Go home        away ∧ nothing to do ∧ 3 quiet ticks → GoHome
    └── Idle           → DoNothing (listen; the scheduler and the resident speak when the robot waits)

Thresholds, each with its reason (also in ``docs/study.md``):

* **Ring the bell up to 3 times** (:data:`RING_ATTEMPTS`): a resident comes to the door
  with probability ~0.9 per ring (the domain's 0.8 and the study's ``answers_door`` 0.95),
  so 3 rings miss a resident who is in ~0.1 % of cases; a no-answer also includes a
  greeting the recogniser lost, which grows with the word error rate.
* **Back off 2 ticks after a failed contact** (:data:`CONTACT_BACKOFF_TICKS`): ringing
  again at once annoys neighbours; two waiting steps (~16 s at the 8 s step timeout)
  also let the scheduler's re-announcement through.
* **Contact budget 6 ticks** (:data:`CONTACT_TICKS`): the drive (1 step, never timed out)
  + 3 rings + 2 spare for a landmark mismatch; a contact that takes longer is stuck.
* **Ask the walk confirmation up to 2 times** (:data:`CONFIRM_ATTEMPTS`): a second
  unanswered question is the point where people start to find a robot tiresome (the
  domain charges -2 per question); she can still ask herself ("let's go", the button).
* **Drive retry 2** (:data:`DRIVE_ATTEMPTS`): the laser reports the wrong landmark in 4 %
  of arrivals (the domain's laser table); one more drive fixes it.
* **3 quiet ticks before going home** (:data:`QUIET_TICKS_BEFORE_HOME`): ~24 s of silence
  after the last service — long enough for a resident to ask a question on arrival (she
  speaks when the robot waits), short enough not to hover.
* **Ignore a reminder announcement for 5 ticks after delivering it**
  (:data:`REANNOUNCE_IGNORE_TICKS`): the scheduler re-announces an outstanding reminder
  every 60 s (``pearl_sim.nursing_home.world.REANNOUNCE_SECONDS``) and an announcement queued before
  the delivery can arrive just after it; 5 steps ≈ 40 s covers that without hiding a
  genuinely new reminder for long.

Ambiguity (when the tree asks instead of acting), from the domain's keyword table
(``config/pearl.domain.yaml``, ``keywords:`` and the ``default`` observation table):

* the touchscreen is unambiguous: ``t_go`` starts the guidance at once;
* a **spoken** ``go`` is ambiguous ("go" is common in small talk, and the recogniser
  confuses "no" with "go"): it is confirmed with ``ConfirmGuideToPhysio``; so is a plain
  ``yes`` to the appointment reminder (she acknowledged the reminder, not the walk);
* a named question (``time``/``weather``, spoken or touched) is explicit in the domain
  ("small talk rarely names the time or the weather") and is answered directly;
* ``unknown`` is not understood *or* silence (the tracker closes a silent step with it;
  speech below the recogniser's ``confidence_floor`` becomes ``unknown`` too, which is how
  a recogniser confidence reaches the tree): it never triggers an action; a leaf waiting
  for an answer counts it as no answer and retries.

Battery: not handled (the world's battery lasts 2 h of driving; an episode drives minutes).
"""
from __future__ import annotations

import itertools
import math
from typing import Callable, List, Optional

import py_trees
from py_trees.common import Access, Status

from pearl_pomdp.interfaces import Decision, TraceStep

__all__ = ["PearlBehaviourTree", "build_tree", "TickTimeout", "RING_ATTEMPTS", "CONFIRM_ATTEMPTS",
           "CONTACT_BACKOFF_TICKS", "CONTACT_TICKS", "DRIVE_ATTEMPTS", "QUIET_TICKS_BEFORE_HOME",
           "REANNOUNCE_IGNORE_TICKS"]

RING_ATTEMPTS = 3
CONTACT_BACKOFF_TICKS = 2
CONTACT_TICKS = 6
CONFIRM_ATTEMPTS = 2
DRIVE_ATTEMPTS = 2
QUIET_TICKS_BEFORE_HOME = 3
REANNOUNCE_IGNORE_TICKS = 5
#: A tick in which no leaf chose an action (a Retry decorator returns RUNNING on its child's
#: failure without re-ticking it; a branch finished) is followed by another, at most this many.
MAX_TICKS_PER_STEP = 4

#: Observation symbols (the Pearl domain's modalities).
TIMEOUT = "unknown"
YES = ("yes", "t_yes")
NO = ("no", "t_no")
LANDMARKS = {"atHome": "home", "atRoom": "room", "atPhysio": "physio"}
QUESTIONS = {"time": "time", "t_time": "time", "weather": "weather", "t_weather": "weather"}
REMIND = {"physio": "RemindPhysioAppt", "vitamin": "RemindVitamin", "checklist": "UpdateChecklist"}
TELL = {"time": "TellTime", "weather": "TellWeather"}
#: The battery driver's readings (the day domain's Charge input, docs/day.md protocol 3): the robot's own.
BATTERY_READINGS = ("battery_low", "battery_ok")
MOVES = ("GotoPatientRoom", "GuideToPhysio", "GoHome")

#: Every blackboard key the tree uses (relative to the tree's own namespace).
KEYS = ("heard", "last_action", "action", "location", "contact", "pending", "question", "walk_requested",
        "walk_offer", "guiding", "quiet", "backoff", "ignore_reminder", "docked")

_instances = itertools.count()


def _answered(heard: str) -> bool:
    """Someone replied (speech or touch): not silence, not the scheduler, not the laser, not the battery."""
    return (heard != TIMEOUT and not heard.startswith("g_") and heard not in LANDMARKS
            and heard not in BATTERY_READINGS)


# ------------------------------------------------------------------ behaviours
class _PearlBehaviour(py_trees.behaviour.Behaviour):
    """A behaviour with a blackboard client on the tree's namespace (read/write ``keys``)."""

    def __init__(self, name: str, namespace: str, reads=(), writes=()):
        super().__init__(name=name)
        self.bb = self.attach_blackboard_client(name=name, namespace=namespace)
        for key in set(reads) - set(writes):
            self.bb.register_key(key=key, access=Access.READ)
        for key in writes:
            self.bb.register_key(key=key, access=Access.WRITE)


class Guard(_PearlBehaviour):
    """A condition on the blackboard: SUCCESS when ``predicate(bb)`` holds, else FAILURE."""

    def __init__(self, name: str, namespace: str, predicate: Callable, reads=KEYS):
        super().__init__(name, namespace, reads=reads)
        self.predicate = predicate

    def update(self) -> Status:
        return Status.SUCCESS if self.predicate(self.bb) else Status.FAILURE


class Act(_PearlBehaviour):
    """A primitive action leaf: it chooses its action on the first tick (RUNNING), and on the
    next tick — the step it opened has closed — judges what was heard.

    ``judge(bb)`` returns SUCCESS, FAILURE, or ``None`` to wait one more step with the same
    action (an idle leaf listens on). ``action`` may be a callable of the blackboard (the
    reminder leaf says the pending reminder's kind).
    """

    def __init__(self, name: str, namespace: str, action, judge: Callable[[object], Optional[Status]],
                 writes=KEYS):
        super().__init__(name, namespace, reads=KEYS, writes=writes)
        self.action = action
        self.judge = judge
        self.waiting = False
        self.judged = False
        self.verdict: Optional[Status] = None

    def initialise(self) -> None:
        self.waiting = self.judged = False
        if self.name != "Idle":
            self.bb.quiet = 0

    def step_closed(self) -> None:
        """The step this leaf opened closed: judge it now, so its effect on the blackboard
        (reminder delivered, contact made) is recorded even if a higher-priority branch
        pre-empts this leaf on the next tick."""
        if self.waiting and not self.judged:
            self.verdict, self.judged = self.judge(self.bb), True

    def update(self) -> Status:
        if self.waiting:
            verdict = self.verdict if self.judged else self.judge(self.bb)
            self.judged = False
            if verdict is not None:
                self.waiting = False
                return verdict
        self.bb.action = self.action(self.bb) if callable(self.action) else self.action
        self.waiting = True
        return Status.RUNNING


class TickTimeout(py_trees.decorators.Decorator):
    """FAILURE when the child is still RUNNING after ``ticks`` ticks (py_trees' own
    :class:`~py_trees.decorators.Timeout` counts wall-clock seconds; a robot's dialog is
    better bounded in steps, whose length the step timeout already sets)."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, ticks: int):
        super().__init__(name=name, child=child)
        self.ticks = int(ticks)
        self.count = 0

    def initialise(self) -> None:
        self.count = 0

    def update(self) -> Status:
        self.count += 1
        if self.decorated.status == Status.RUNNING and self.count > self.ticks:
            self.feedback_message = f"timed out after {self.ticks} ticks"
            return Status.FAILURE
        return self.decorated.status


class Effect(_PearlBehaviour):
    """Writes to the blackboard and returns ``status`` (a give-up or back-off branch)."""

    def __init__(self, name: str, namespace: str, effect: Callable, status: Status = Status.FAILURE):
        super().__init__(name, namespace, reads=KEYS, writes=KEYS)
        self.effect, self.status_out = effect, status

    def update(self) -> Status:
        self.effect(self.bb)
        return self.status_out


# ------------------------------------------------------------------ judges
def _arrived(place: str):
    def judge(bb):
        return Status.SUCCESS if bb.location == place and bb.heard in LANDMARKS else Status.FAILURE
    return judge


def _ring_judge(bb):
    if _answered(bb.heard):
        bb.contact = True
        return Status.SUCCESS
    return Status.FAILURE


def _remind_judge(bb):
    # Spoken in contact: delivered (the scheduler re-announces one that was not).
    kind = bb.pending[0] if bb.pending else None
    if kind is not None:
        bb.pending = bb.pending[1:]
        ignore = dict(bb.ignore_reminder)
        ignore[kind] = REANNOUNCE_IGNORE_TICKS
        bb.ignore_reminder = ignore
        if kind == "physio" and not bb.walk_requested:
            bb.walk_offer = True   # she acknowledged the reminder; the walk is offered next
    return Status.SUCCESS


def _confirm_walk_judge(bb):
    if bb.heard in YES or bb.heard in ("go", "t_go"):
        bb.walk_requested, bb.walk_offer = True, False
        return Status.SUCCESS
    if bb.heard in NO:
        bb.walk_requested, bb.walk_offer = False, False
        return Status.SUCCESS
    return Status.FAILURE       # not understood or silence: ask again (Retry)


def _guide_judge(bb):
    if bb.location == "physio" and bb.heard in LANDMARKS:
        bb.guiding, bb.walk_requested = True, False
        return Status.SUCCESS
    return Status.FAILURE


def _terminate_judge(bb):
    bb.guiding = False
    return Status.SUCCESS


def _tell_judge(bb):
    bb.question = None
    return Status.SUCCESS


def _idle_judge(bb):
    bb.quiet = bb.quiet + 1
    return None


def _nothing_to_do(bb) -> bool:
    return not (bb.pending or bb.question or bb.walk_requested or bb.walk_offer or bb.guiding)


def _docked_judge(bb):
    bb.docked = bb.location == "home"
    return Status.SUCCESS


def build_tree(namespace: str, day_rules: bool = False) -> py_trees.behaviour.Behaviour:
    """The Pearl tree (see the module docstring), its blackboard keys under ``namespace``.

    ``day_rules`` adds the working day's rule (docs/day.md, fixed before any POMDP ran on days):
    **Dock** — at the station and not docked → ``RechargeBattery``, just above Idle, so the robot is
    on its charger whenever it is home with nothing to do. With the existing *Go home* (nothing to do
    for :data:`QUIET_TICKS_BEFORE_HOME` quiet ticks) it covers "dock when low" without a battery
    reading, which neither controller has (the domain's Battery is hidden).
    """
    ns = namespace
    seq = py_trees.composites.Sequence
    sel = py_trees.composites.Selector

    end_guidance = seq("End guidance", memory=True, children=[
        Guard("Guiding at physio?", ns, lambda bb: bb.guiding and bb.location == "physio"),
        Act("TerminateGuidance", ns, "TerminateGuidance", _terminate_judge),
    ])
    inform = sel("Inform", memory=False, children=[
        seq(f"Tell {kind}", memory=True, children=[
            Guard(f"Asked the {kind}?", ns, lambda bb, k=kind: bb.question == k),
            Act(TELL[kind], ns, TELL[kind], _tell_judge),
        ]) for kind in ("time", "weather")
    ])
    guide = seq("Guide", memory=True, children=[
        Guard("Walk requested?", ns, lambda bb: bb.walk_requested and bb.contact and bb.location == "room"),
        py_trees.decorators.Retry("Drive retry", Act("GuideToPhysio", ns, "GuideToPhysio", _guide_judge),
                                  num_failures=DRIVE_ATTEMPTS),
    ])
    make_contact = seq("Make contact", memory=True, children=[
        sel("At the room", memory=True, children=[
            Guard("At the room?", ns, lambda bb: bb.location == "room"),
            py_trees.decorators.Retry("Drive retry", Act("GotoPatientRoom", ns, "GotoPatientRoom", _arrived("room")),
                                      num_failures=DRIVE_ATTEMPTS),
        ]),
        py_trees.decorators.Retry("Ring retry", Act("RingDoorBell", ns, "RingDoorBell", _ring_judge),
                                  num_failures=RING_ATTEMPTS),
    ])
    contact = sel("Contact", memory=True, children=[
        Guard("In contact?", ns, lambda bb: bb.contact),
        TickTimeout("Contact budget", make_contact, ticks=CONTACT_TICKS),
    ])
    remind = sel("Remind", memory=True, children=[
        seq("Deliver reminder", memory=True, children=[
            Guard("Reminder pending?", ns, lambda bb: bool(bb.pending) and bb.backoff == 0),
            contact,
            Act("Remind", ns, lambda bb: REMIND[bb.pending[0]], _remind_judge),
        ]),
        # A failed contact (no answer) backs off before the next try; the branch fails.
        Effect("Back off", ns, lambda bb: setattr(bb, "backoff", CONTACT_BACKOFF_TICKS) if bb.pending else None),
    ])
    offer = sel("Offer walk", memory=True, children=[
        seq("Confirm walk", memory=True, children=[
            Guard("Walk offered?", ns, lambda bb: bb.walk_offer and bb.contact and bb.location == "room"),
            py_trees.decorators.Retry("Ask retry", Act("ConfirmGuideToPhysio", ns, "ConfirmGuideToPhysio",
                                                        _confirm_walk_judge), num_failures=CONFIRM_ATTEMPTS),
        ]),
        Effect("Give up offer", ns, lambda bb: setattr(bb, "walk_offer", False)),
    ])
    go_home = seq("Go home", memory=True, children=[
        Guard("Done here?", ns, lambda bb: bb.location != "home" and _nothing_to_do(bb)
              and bb.quiet >= QUIET_TICKS_BEFORE_HOME),
        Act("GoHome", ns, "GoHome", _arrived("home")),
    ])
    idle = Act("Idle", ns, "DoNothing", _idle_judge)
    dock = seq("Dock", memory=True, children=[
        Guard("Home, not docked?", ns, lambda bb: bb.location == "home" and not bb.docked),
        Act("RechargeBattery", ns, "RechargeBattery", _docked_judge),
    ])
    # "Offer walk" only runs when offered (its give-up Effect fails it otherwise, so the
    # selector falls through to Go home / Idle).
    offer_guarded = seq("Offer walk?", memory=True, children=[
        Guard("Offer pending?", ns, lambda bb: bb.walk_offer), offer])
    remind_guarded = seq("Remind?", memory=True, children=[
        Guard("Any reminder?", ns, lambda bb: bool(bb.pending) and bb.backoff == 0), remind])
    branches = [end_guidance, inform, guide, remind_guarded, offer_guarded, go_home] + ([dock] if day_rules else [])
    return sel("Pearl", memory=False, children=branches + [idle])


class PearlBehaviourTree:
    """The tree as an :class:`~pearl_pomdp.interfaces.ObservingDecider` (and a Controller:
    ``name`` and ``decider``), for the study, the demo and :mod:`pearl_sim.nursing_home.bt_node`.

    Args:
        name: the controller's name in the study (``behaviour_tree``).
        actions: the model's action names (a decision carries the index into them).
        day_rules: add the working day's *Dock* rule (:func:`build_tree`; the day study's ``day_tree``).
    """

    def __init__(self, name: str = "behaviour_tree", actions: Optional[List[str]] = None, day_rules: bool = False):
        self.name = name
        self.day_rules = bool(day_rules)
        self.decider = self
        if actions is None:
            from pearl_sim.nursing_home.scenario import default_domain

            actions = default_domain().actions
        self._index = {a: i for i, a in enumerate(actions)}
        self.namespace = f"/pearl_bt_{next(_instances)}"
        self.root = build_tree(self.namespace, day_rules=self.day_rules)
        self.tree = py_trees.trees.BehaviourTree(self.root)
        self.blackboard = py_trees.blackboard.Client(name=f"{name} executive", namespace=self.namespace)
        for key in KEYS:
            self.blackboard.register_key(key=key, access=Access.WRITE)
        self.reset()

    def __reduce__(self):
        # py_trees nodes hold generators (a tick in progress) and cannot be pickled: a copy sent
        # to another process (pearl experiment --cluster) is a fresh tree, as every episode
        # starts from one (reset()).
        return (type(self), (self.name, sorted(self._index, key=self._index.__getitem__), self.day_rules))

    # ---------------------------------------------------------------- ObservingDecider
    def reset(self) -> None:
        """A fresh episode: every node INVALID, the blackboard at the start of the day."""
        self.root.stop(Status.INVALID)
        self._emitter: Optional[Act] = None
        bb = self.blackboard
        bb.heard, bb.last_action, bb.action = TIMEOUT, None, None
        bb.location, bb.contact, bb.guiding = "home", False, False
        bb.pending, bb.question, bb.ignore_reminder = [], None, {}
        bb.walk_requested, bb.walk_offer = False, False
        bb.quiet, bb.backoff = 0, 0
        bb.docked = True            # the day starts on the charger

    def observe(self, action: str, observation: str) -> None:
        """A step closed: ``action`` opened it, ``observation`` closed it → the blackboard."""
        bb = self.blackboard
        bb.heard, bb.last_action = observation, action
        bb.backoff = max(0, bb.backoff - 1)
        bb.ignore_reminder = {k: n - 1 for k, n in bb.ignore_reminder.items() if n > 1}
        if action in MOVES:
            # The robot left: only a guided resident is still with it.
            bb.contact = bool(bb.contact and action == "GuideToPhysio" and bb.walk_requested)
            bb.docked = False       # any drive leaves the charger
        if observation in LANDMARKS:
            bb.location = LANDMARKS[observation]
        elif observation.startswith("g_") and observation != "g_none":
            kind = observation[2:]
            if kind not in bb.pending and kind not in bb.ignore_reminder:
                bb.pending = bb.pending + [kind]
        elif observation in QUESTIONS:
            bb.question = QUESTIONS[observation]
        elif observation == "t_go" and bb.contact and not bb.guiding:
            bb.walk_requested, bb.walk_offer = True, False     # the button is unambiguous
        elif observation == "go" and bb.contact and bb.location == "room" and not bb.guiding \
                and not bb.walk_requested:
            bb.walk_offer = True                               # spoken 'go' heard once: confirm it
        if self._emitter is not None:
            self._emitter.step_closed()
            self._emitter = None

    def execute(self, belief=None) -> Decision:
        """Tick the tree; the action the tree chose (the belief is not used)."""
        bb = self.blackboard
        bb.action = None
        ticks = 0
        while bb.action is None and ticks < MAX_TICKS_PER_STEP:
            self.tree.tick()
            ticks += 1
        action = bb.action if bb.action is not None else "DoNothing"
        tip = self.root.tip()
        self._emitter = tip if isinstance(tip, Act) and tip.waiting else None
        where = tip.name if tip is not None else "Pearl"
        return Decision(self._index[action], action, [TraceStep(self.name, where, math.nan),
                                                      TraceStep(where, action, math.nan)])

    def snapshot(self) -> dict:
        """The blackboard's values (for tests and transcripts)."""
        return {key: getattr(self.blackboard, key) for key in KEYS}
