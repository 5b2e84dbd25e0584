"""Mitsuba 3: the fast CPU backend, and the exact ray casts behind labels through a lens and annotate."""
