"""Identify a structure with PIDynNet: ``python train.py system=bouc_wen noise=0.05``."""

from pidyn.cli import train_main

if __name__ == "__main__":
    train_main()
