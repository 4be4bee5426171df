"""Pseudo-arclength continuation of a solution branch ``R(z; p) = 0`` (any residual): see
:mod:`.driver`. The names importable from here are those the package, its tests, benchmarks,
validation and examples use."""

from .driver import (CHORD_ITERATION_WORK, MESSAGES, SEGMENT_POINTS, _JIT_CACHE, Branch, IllinoisBracket, PointKind,
                     PseudoArclength, Status, _Compiled, _jit_corrector, _python_corrector, continuation, illinois,
                     sweep_method)

__all__ = ["PseudoArclength", "continuation", "sweep_method", "Branch", "Status", "PointKind"]
