"""Dynamics, tube design, nominal FHOCP/MPC, closed-loop simulation and Algorithm 1."""
