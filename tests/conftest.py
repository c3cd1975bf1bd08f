"""Settings shared by every test."""

from hypothesis import settings

# Property tests judge outcomes, never speed: a machine that stalls for a moment (a loaded
# CI runner, a busy VM) must not fail one by hypothesis's per-example deadline.
settings.register_profile("fcmaster", deadline=None)
settings.load_profile("fcmaster")
