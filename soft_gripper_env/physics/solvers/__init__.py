"""Solvers: Newton's method (one compiled loop for rods on their own and for rods with a free body), the contact
corrector around it (one compiled loop for fixed and free objects), the time integrators, and the records a step
reads and writes. They use the kernels and the scene descriptions, never the simulator above them."""
