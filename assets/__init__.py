"""Shipped data: the LinkD checkpoint, its model card, and example curves and mechanisms."""
