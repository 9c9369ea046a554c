"""The skill layer: demonstrations (:mod:`.demonstration`), ROS bags (:mod:`.bags`), the skill
(:mod:`.skill`), its reproduction by probabilistic inverse kinematics (:mod:`.probabilistic_ik`,
on the generalized constraints of :mod:`.constraints`), the online controller
(:mod:`.controller`) and generated data sets (:mod:`.datasets`).

Built on :mod:`pbdkit.prob`, :mod:`pbdkit.robots` and :mod:`pbdkit.motion`; never imports the
simulator, OpenCV or matplotlib."""
