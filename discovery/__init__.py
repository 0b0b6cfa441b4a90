"""Model discovery: find where simulation and flight data disagree, name the missing effect, fit it."""
