"""Integrators: each renders batches of camera samples into a :class:`~ercuts_core.film.Film`."""
