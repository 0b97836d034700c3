"""Developer tools, not needed to use or measure the env: a refactor's guard (``golden_outputs``), this tree's speed
and compile time against an older commit's in one run (``compare_commits``, ``first_step``), and where an env
step's time and reference counts go (``profile_env``, ``refcounts``). Run each from the repository root as a
module, e.g. ``python -m tools.compare_commits --base HEAD~1 --paired``."""
