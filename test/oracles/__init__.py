"""Readable numpy versions of the physics and the barriers, kept only to check the compiled core
(rta_attitude.dynamics, rta_attitude.constraints) against a second, independent implementation.

They are the first implementation of the project, written from SPEC.md in vectorised numpy; the
compiled kernels were written later and separately, so agreement between the two (to rounding) is
evidence for both. Nothing in rta_attitude/ imports them.
"""
