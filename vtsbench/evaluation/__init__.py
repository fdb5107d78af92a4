"""Scoring: the tasks (declared once in tasks.py), metrics (pure numpy), submission reading and
validation, typed results (result.py), reports and leaderboards."""
