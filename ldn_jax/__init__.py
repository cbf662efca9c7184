"""MBRL-LDN in JAX."""
