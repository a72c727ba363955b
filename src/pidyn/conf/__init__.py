"""Hydra configs of pidyn, shipped inside the package so the commands run from any directory."""
