"""Measurements behind `mapctl bench ...`: they return figures, never judge them."""
