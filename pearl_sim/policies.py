"""The controllers the study can compare, by name (no imports: `pearl --help` lists them cheaply)."""

#: Every controller ``pearl experiment --policies`` accepts.
POLICY_NAMES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", "behaviour_tree", "scripted")
#: The study's default comparison: the behaviour tree is the main non-POMDP baseline
#: (``scripted`` stays available by name).
DEFAULT_POLICIES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", "behaviour_tree")
