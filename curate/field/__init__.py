"""The CPU grid radiance field: model, training, rendering and metrics."""
