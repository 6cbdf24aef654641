"""The ward: a third simulated world, for ``config/ward.domain.yaml`` (docs/ward.md).

One robot, three residents (Ann, Bob, Cleo), each with their own room, medication reminders and
requests; they move between their room and the lounge. The world (:mod:`.world`), its scenarios
(:mod:`.scenario`), its py_trees baseline for several residents (:mod:`.behaviour_tree`) and its
study (:mod:`.study`, :mod:`.experiment`) plug into the same episode loop as the other worlds
(:func:`pearl_sim.loop.run_episode`) through the same world interface (``act``/``wait``/``time``/``scenario``).
"""
from pearl_sim.worlds import SimWorld

#: The ward as a registered world (entry point ``pearl.worlds: ward``), run by the frame; its demo runs the
#: first episode of its study file.
WORLD = SimWorld("ward", "the ward: one robot, three residents with medication reminders and requests",
                 "config/scenarios/ward/study.yaml", "config/scenarios/ward/study.yaml", "config/ward_nodes.yaml",
                 demo="pearl_sim.ward.demo:DEMO", experiment="pearl_sim.ward.experiment:EXPERIMENT")
