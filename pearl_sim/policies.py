"""The controllers the study can compare, by name (no imports: `pearl --help` lists them cheaply)."""

#: Every controller ``pearl experiment --policies`` accepts.
POLICY_NAMES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", "behaviour_tree", "scripted")
#: The study's default comparison: the behaviour tree is the main non-POMDP baseline
#: (``scripted`` stays available by name).
DEFAULT_POLICIES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", "behaviour_tree")
#: Trials of the flat point-based solve in the study: a budget that is not wall-clock time, so
#: the same seed plans the same flat policy on a busy and on a quiet machine.
DEFAULT_FLAT_TRIALS = 100
