"""The controllers the study can compare, by name (no imports: `pearl --help` lists them cheaply)."""

#: Every controller ``pearl experiment --policies`` accepts.
POLICY_NAMES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", "behaviour_tree", "scripted")
#: The study's default comparison: the behaviour tree is the main non-POMDP baseline
#: (``scripted`` stays available by name).
DEFAULT_POLICIES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", "behaviour_tree")
#: Trials of the flat point-based solve in the study: a budget that is not wall-clock time, so
#: the same seed plans the same flat policy on a busy and on a quiet machine.
DEFAULT_FLAT_TRIALS = 100
#: Steps of exact forward search at execution for the flat point-based policy: the same one
#: step the hierarchy's root takes (``lookahead: 1`` in config/pearl.hierarchy.yaml). Greedy on
#: the lower-bound vectors of a 100-trial solve, the flat policy asked ConfirmGuideToPhysio
#: for ever after the reminder, in the model's own simulation as in the world (its trials
#: rarely reach the beliefs after a reminder, which b0 makes rare); one Bellman step over the
#: true model guides.
FLAT_LOOKAHEAD = 1
