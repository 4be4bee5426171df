"""Validation of hbgear against time integration, known answers and the paper's figures.

``python -m validation`` (from the repository root) regenerates every figure in
``validation/figures/`` and ``validation/REPORT.md``; see :mod:`validation.run_all`.
Not part of the test suite (``pytest`` only collects ``tests/``).
"""
