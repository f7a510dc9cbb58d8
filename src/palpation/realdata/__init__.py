"""Real datasets (Silicone, Meat) rebuilt from the shipped reference videos."""
