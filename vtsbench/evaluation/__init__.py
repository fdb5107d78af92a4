"""Scoring: metrics (pure numpy), submission reading and validation, reports and leaderboards."""
