"""Examples: the paper's figures, the cantilever, water against air and a video of the env. Run each from the
repository root as a module, e.g. ``python -m examples.reproduce_paper --out out/paper``."""
