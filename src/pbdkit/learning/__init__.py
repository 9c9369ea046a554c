"""The skill layer: demonstrations (:mod:`.demonstration`), ROS bags (:mod:`.bags`), the skill
(:mod:`.skill`), its reproduction by probabilistic inverse kinematics (:mod:`.probabilistic_ik`:
the generalized constraints of :mod:`.constraints` fused by the controllers' steps of
:mod:`.steps` and, for oriented constraints, :mod:`.pose_steps`), the online controller
(:mod:`.controller`) and generated data sets (:mod:`.datasets`).

Built on :mod:`pbdkit.prob`, :mod:`pbdkit.robots` and :mod:`pbdkit.motion`; never imports the
simulator, OpenCV or matplotlib."""
