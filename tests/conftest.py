import os
import sys

import hypothesis

import ijoy_jax.sim  # noqa: F401  headless: selects MUJOCO_GL=egl before any test module imports mujoco

sys.path.insert(0, os.path.dirname(__file__))  # tests/reference.py

hypothesis.settings.register_profile("ci", derandomize=True, deadline=None, max_examples=40,
                                     print_blob=True)
hypothesis.settings.load_profile("ci")
