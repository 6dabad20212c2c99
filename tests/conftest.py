import os
import sys

import hypothesis

sys.path.insert(0, os.path.dirname(__file__))  # tests/reference.py

hypothesis.settings.register_profile("ci", derandomize=True, deadline=None, max_examples=40,
                                     print_blob=True)
hypothesis.settings.load_profile("ci")
