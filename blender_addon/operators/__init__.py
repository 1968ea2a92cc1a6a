"""Operators: each module owns one user action."""
