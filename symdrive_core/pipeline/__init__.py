"""From a scene package to outputs: plan the stages a scene needs, run them, report."""
