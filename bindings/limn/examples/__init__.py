"""Demos and the gradient bench, run from the command line; not part of the library API.

    python3 -m limn demo [multiview]    multiview.py:   a bumpy shape recovered from three images
    python3 -m limn demo shadows        shadows.py:     a shape recovered from its two shadows on a
                                                        curved wall (the scene ships in scenes/shadow_wall)
    python3 -m limn demo heightfield    heightfield.py: the heightfield paper's optimisations
    python3 -m limn bench               bench.py:       gradient error against run time, against a
                                                        finite-difference reference

They use only limn's public API (``limn.load_dict``, ``limn.optim``, ...) and show how to drive it;
their functions and options may change without notice. ``import limn`` does not import them.
"""
