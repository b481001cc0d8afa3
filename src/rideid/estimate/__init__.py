"""Estimation: the cost, JADE, sensitivity maps and the identification orchestrator."""
