"""The nursing home: Pearl's own simulated world, for ``config/pearl.domain.yaml`` (docs/simulation.md).

One resident, a scheduler and the robot Pearl: appointment reminders, guidance to physiotherapy at
her pace, time and weather questions. The episode world (:mod:`.world`), its scenarios
(:mod:`.scenario`), the study's residents (:mod:`.residents`) and its py_trees baseline
(:mod:`.behaviour_tree`) plug into the same episode loop as the reception and the ward
(:func:`pearl_sim.loop.run_episode`) through the same world interface (``act``/``wait``/``time``/``scenario``).
"""
from pearl_sim.worlds import SimWorld

#: The nursing home as a registered world (entry point ``pearl.worlds: pearl``); its demo (Figure 4, the
#: live view, the belief plot) and its study (residents, SNR axes, the cluster) are its own runners.
WORLD = SimWorld("pearl", "the nursing home: a resident, reminders, guidance to physiotherapy",
                 "config/scenarios/figure4.yaml", "config/scenarios/study.yaml", "config/pearl_nodes.yaml",
                 demo="pearl_sim.cli.demo:run_nursing_home", experiment="pearl_sim.cli.experiment:run_nursing_home")
