"""Tables and figures of the trained runs (Fig. 6, Tables 3 and 4 upper half) beside the paper's numbers."""
