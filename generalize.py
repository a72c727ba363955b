"""Predict the response to unseen earthquakes: ``python generalize.py system=bouc_wen``."""

from pidyn.cli import generalize_main

if __name__ == "__main__":
    generalize_main()
