"""Analysis of measurements: FRFs, resonance fitting, video tracking, comparison and reports."""
