"""Independent checks of a test (Theorems 1, 2): graph search and max flow only."""
