"""Pure planning: numbers in, numbers out. No sockets, files or clocks.

Implements sections III-IV of the paper (as read in docs/design.md):
graph nodes and edges, the robust Algorithm 1, line-formation kinematics, guarantee checks.
"""
