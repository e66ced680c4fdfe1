"""Problems: the Problem value, problem files (TOML), built-ins, random grids, size limits."""
