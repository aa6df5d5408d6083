"""Validation references (not on the simulation path; need scipy: ``pip install oxyline[reference]``).

``axisymmetric``: 2-D axisymmetric advection–diffusion of O2 in a straight rigid tube with a
Womersley velocity profile (docs/validation-oxygen.md, docs/physics.md §6).
"""
