"""Pure numerics of acs-twin: the spacecraft plant, onboard ACS algorithms and the batch engine.

No I/O, no web, no database (DESIGN.md). SI units inside; quaternions scalar-first Hamilton.
"""
