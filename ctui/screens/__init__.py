"""Textual screens and widgets of the ctui terminal app (thin: they call ctui.engine)."""
