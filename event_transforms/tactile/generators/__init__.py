"""The tactile generators' parts: :mod:`~event_transforms.tactile.generators.optical`, the optical
generator (an event-based GelSight rendered with ``taxim``; ``pip install 'event-transforms[optical]'``).
The built-in generator is :mod:`event_transforms.tactile.simulation`. Both see their scene through
the library's one DVS pixel model: the optical generator calls
:func:`~event_transforms.functional.emulate_events` on its rendered frames, the built-in one
:func:`~event_transforms.functional.threshold_crossings`, :func:`~event_transforms.functional.camera_pixels`
and :func:`~event_transforms.functional.noise_events` on the pixels its strip can touch.
"""
