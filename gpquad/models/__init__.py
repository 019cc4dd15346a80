"""Identified models: equations and their exports, analysis, rollout scoring."""
