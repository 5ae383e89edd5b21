"""The task: what the robot must do with the patient's limb and what counts as doing it well
or dangerously. Exercises in clinical terms (:mod:`.exercises`), the robot targets they
become (:mod:`.targets`), where the robot may go (:mod:`.workspace`), the observation layout
(:mod:`.observation`), the named reward terms (:mod:`.reward`) and the checks that a
patient can do an exercise at all (:mod:`.feasibility`); the safety rules run with the
physics (:mod:`rehabbot.sim.physics`). Built on :mod:`rehabbot.sim`; knows nothing of
Gymnasium or RL.
"""
