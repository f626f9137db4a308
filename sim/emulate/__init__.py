"""Emulators of the cell's devices on their real wires (pseudo-terminals, loopback sockets), each
backed by the PyBullet twin, so the real drivers run against them unchanged.

Each module documents its backend interface at the top: a small Protocol the twin implements
(and that a test may implement with anything else). ``docs/emulator.md`` says what each
emulator models, from which reference, and what only the real hardware proves.
"""
