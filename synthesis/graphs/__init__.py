"""Automata of the objectives and the product graphs G and G_sys (docs/method.md §3-4)."""
