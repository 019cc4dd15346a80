"""Head-to-head identification benchmark: scenarios, peers, scoring, tables."""
