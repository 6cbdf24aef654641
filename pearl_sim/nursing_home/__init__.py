"""The nursing home: Pearl's own simulated world, for ``config/pearl.domain.yaml`` (docs/simulation.md).

One resident, a scheduler and the robot Pearl: appointment reminders, guidance to physiotherapy at
her pace, time and weather questions. Everything of this world is here, beside ``reception/`` and
``ward/``: the episode world (:mod:`.world`), its scenarios (:mod:`.scenario`), the study's residents
(:mod:`.residents`), its py_trees baseline (:mod:`.behaviour_tree`, and as a node :mod:`.bt_node`),
the study (:mod:`.experiment`: one episode scored; :mod:`.agents`, :mod:`.study`, :mod:`.episodes`),
the Figure 4 demo through the graph (:mod:`.demo`), the working day (:mod:`.day`, :mod:`.day_study`,
:mod:`.day_graph`, :mod:`.day_plot`) and the simulator node of ``launch/pearl_sim.launch.xml``
(:mod:`.world_node`). They plug into the same episode loop as the other worlds
(:func:`pearl_sim.loop.run_episode`) through the same world interface (``act``/``wait``/``time``/``scenario``).
"""
from pearl_sim.worlds import SimWorld

#: The nursing home as a registered world (entry point ``pearl.worlds: pearl``); its demo is the frame's
#: with Pearl's hooks and the live view (:mod:`.demo`), its study (residents, SNR axes, the cluster) its own runner.
WORLD = SimWorld("pearl", "the nursing home: a resident, reminders, guidance to physiotherapy",
                 "config/scenarios/figure4.yaml", "config/scenarios/study.yaml", "config/pearl_nodes.yaml",
                 demo="pearl_sim.cli.demo:run_nursing_home", experiment="pearl_sim.cli.experiment:run_nursing_home")
