"""Sharing datasets: the Hugging Face Hub (publish, pull, load with a Hub fallback) and the committed cards."""
