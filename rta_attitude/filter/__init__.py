"""The ASIF safety filter: the QP over the barrier rows, its exact active-set solver (proxsuite as an
option) and the filter's result record."""
