"""The tactile generators' parts: :mod:`~event_transforms.tactile.generators.dvs`, the built-in
simulator's numpy DVS pixel model (the model of the library's
:func:`~event_transforms.functional.emulate_events`, which the optical generator uses), and :mod:`~event_transforms.tactile.generators.optical`, the
optical generator (an event-based GelSight rendered with ``taxim``; ``pip install
'event-transforms[optical]'``). The built-in generator is :mod:`event_transforms.tactile.simulation`.
"""
