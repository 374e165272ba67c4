"""The simulated world (true robot + effects + noise), measurement plans and the tracker."""
