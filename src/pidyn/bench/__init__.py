"""What the studies under ``experiments/`` share: their command line and process pool
(``grid``), a logged subprocess (``launch``), the seeded buildings they draw (``draws``) and
their tables' cells and run folders (``tables``).
Nothing in the package imports it; the studies import it from here, not by path."""
