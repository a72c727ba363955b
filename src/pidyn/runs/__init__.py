"""One identification run at the edge of the package: built from a Hydra config, the methods
beside PIDynNet, and what it writes to its folder. The tasks (``pidyn.tasks``) wire these."""
