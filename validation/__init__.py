"""Validation references and studies of the repository, not shipped in the wheel (not on the
simulation path; need scipy). Tests and benches import them from the repository root
(``pytest`` puts it on ``sys.path``: ``pythonpath`` in pyproject.toml); studies run as
``python -m validation.closures`` from the repository root.

``axisymmetric``: 2-D axisymmetric advection–diffusion of O2 in a straight rigid tube with a
Womersley velocity profile (docs/validation-oxygen.md, docs/physics.md §6).
"""
