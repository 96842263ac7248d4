"""mesh stage."""
