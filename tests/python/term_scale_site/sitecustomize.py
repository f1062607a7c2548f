"""On PYTHONPATH only while LIMN_TERM_SCALE / LIMN_SEED_OFFSET is set (conftest.py puts it there):
installs tests/python/term_scale.py's hook in subprocesses, e.g. ``python -m limn demo``."""
import os
import sys

if os.environ.get("LIMN_TERM_SCALE") or os.environ.get("LIMN_SEED_OFFSET") or os.environ.get("LIMN_TERM_MEMO"):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import term_scale
    term_scale.install()
