"""The filter registry: each stage operation a plain function with typed keyword parameters, by name."""
