"""The twin loop (docs/twin.md): compare a captured session of a real motor with the
virtual motor, and fit the machine file's load and servo model to it.
"""
