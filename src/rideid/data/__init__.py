"""The data layer: file schemas and readers, conditioning of measured runs, datasets and scenarios."""
