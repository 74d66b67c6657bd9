"""The fixed-point numerics of implicit coupling (paper 2.3, Step 5): the time loop
(:mod:`.loop`), Aitken and IQN-ILS acceleration (:mod:`.acceleration`) and mass-weighted
residual norms (:mod:`.convergence`). No processes, no physics."""
