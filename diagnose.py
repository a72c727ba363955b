"""Find what a model gets wrong: ``python diagnose.py data=silverbox system=linear``."""

from pidyn.cli import diagnose_main

if __name__ == "__main__":
    diagnose_main()
