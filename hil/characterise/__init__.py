"""Characterising a unit type: a population of simulated units drawn across the profile's
tolerances, calibrated as a test engineer would, each result against the truth of its drawn
plant; the method-bias map and its validation come from it (``gimbal-hil characterise``).
"""
