"""Benchmarks behind ``a2cf-mb bench``: each a library function returning a dict of figures."""
