"""The tactile generators' shared parts: :mod:`~event_transforms.tactile.generators.dvs`, the one
DVS pixel model of both generators, and :mod:`~event_transforms.tactile.generators.optical`, the
optical generator (an event-based GelSight rendered with ``taxim``; ``pip install
'event-transforms[optical]'``). The built-in generator is :mod:`event_transforms.tactile.simulation`.
"""
