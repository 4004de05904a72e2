"""Wall-kinematics predictors of the weak scheme (the wall velocity within a coupling step; the wall starts every
step at the mapped MPM interface position):
  constant  the MPM interface velocity at the start of the step (the end position x_n + dt v_n is Kratos'
            linear displacement predictor 2 x_n - x_(n-1)); the wall then jumps by dt (v_(n+1) - v_n) = O(dt^2)
            to the MPM position at the next step, which the contact dashpot never sees: a first-order energy
            error on the DEM side (coupled_subcycling)
  linear    the velocity extrapolated to the end of the step, 2 v_n - v_(n-1) (the MPM moves its boundary
            particles with the end-of-step velocity, x_(n+1) = x_n + dt v_(n+1)): the jump is O(dt^3); an explicit
            extrapolation, unstable at large coupling steps (diverges at ratio 40 in coupled_subcycling)
"""
PREDICTORS = ("constant", "linear")
