"""Your controller under test: the arm in your pytest suite and your launch tests.
Installed as a pytest plugin (entry point pytest11), so its fixtures need no import:

    def test_pd_reaches_the_target(arm):
        trace = arm.run(pd, "release", seconds=3.0, reference=[0.5, -0.3])
        assert trace.settle_time() < 1.5

Import what you use from its module (the package itself imports nothing):
- loop: a Python callable against a scene, in process (closed_loop, Reading);
- wire: the node in lockstep in a subprocess on a private domain (WireArm), and
  controller: a controller on the dds transport for it (Controller);
- trace: what a run leaves and what you assert on (Trace: settle_time, overshoot,
  steady_state_error, tracking_error, peak_torque, books_closed);
- evidence: what a failing test writes (CSV, .rrd, PNG); plugin: the fixtures `arm` and
  `arm_node`; launch: the node's launch actions in lockstep for launch_testing.
May import: every layer below it (tools for the wire's client)."""
