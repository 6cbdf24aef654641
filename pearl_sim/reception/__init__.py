"""The reception hall: a second simulated world, for ``config/reception.domain.yaml`` (docs/reception.md).

A robot at a front desk greets visitors, asks where they want to go, escorts them at their own
pace and hands them over to staff, and docks when its battery runs low. The world
(:mod:`.world`), its scenarios (:mod:`.scenario`), its py_trees baseline (:mod:`.behaviour_tree`),
its study (:mod:`.study`) and its demo through the ROS graph (:mod:`.demo`) plug into the same
episode loop as the nursing home (:func:`pearl_sim.loop.run_episode`) through the same
world interface (``act``/``wait``/``time``/``scenario``): nothing of the nursing home is used.
"""
from pearl_sim.worlds import SimWorld

#: The reception as a registered world (entry point ``pearl.worlds: reception``), run by the frame.
WORLD = SimWorld("reception", "the reception hall: visitors greeted, asked and escorted to the gallery or office",
                 "config/scenarios/reception/one_visitor.yaml", "config/scenarios/reception/study.yaml",
                 "config/reception_nodes.yaml", demo="pearl_sim.reception.demo:DEMO",
                 experiment="pearl_sim.reception.experiment:EXPERIMENT")
