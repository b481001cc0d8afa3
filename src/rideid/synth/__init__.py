"""Synthetic data: simulate a scenario's runs with its true car and write them as a dataset (:mod:`.scenario`)."""
