"""``pearl`` subcommands that belong to the simulator (``demo``, ``experiment``).

They are registered with the ``pearl`` command through the ``pearl.commands`` entry-point
group (``setup.py``), so the core package never imports the simulator.
"""
