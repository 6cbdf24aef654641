"""The nursing home: Pearl's own simulated world, for ``config/pearl.domain.yaml`` (docs/simulation.md).

One resident, a scheduler and the robot Pearl: appointment reminders, guidance to physiotherapy at
her pace, time and weather questions. The episode world (:mod:`.world`), its scenarios
(:mod:`.scenario`), the study's residents (:mod:`.residents`) and its py_trees baseline
(:mod:`.behaviour_tree`) plug into the same episode loop as the reception and the ward
(:func:`pearl_sim.loop.run_episode`) through the same world interface (``act``/``wait``/``time``/``scenario``).
"""
