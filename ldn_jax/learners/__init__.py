"""Learners: loss + update on a batch of (possibly masked) transitions."""
