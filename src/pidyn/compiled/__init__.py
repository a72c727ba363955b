"""Simulation at compiled speed: a system's state rate recorded as a tape of scalar operations
(``tape``), written out as a C RK4 loop with forward sensitivities (``codegen``), compiled and
kept on disk (``build``), and called in place of ``pidyn.integrate``'s Python loop (``kernel``)."""
