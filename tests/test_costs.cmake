# The wall time, in seconds, of every test that takes 2.5 s or more, measured in one
# `ctest -j3` run on an idle 2-core machine (at 962c2ea). ctest starts tests in descending COST
# when its build directory has no timings of its own (Testing/Temporary/CTestCostData.txt), as
# in a fresh clone; without these the long tests started in declaration order, the last of them
# near the end (StudySlurmCluster, 34 s, mostly waiting for its cluster), and the suite took 259 s
# instead of about 220 s (src/docs/speed.md, "Test suite time"). Once ctest has run, its own
# timings take over. To refresh the list after a suite changes a lot:
#   grep -oE 'Test +#[0-9]+: [^ ]+ .* [0-9.]+ sec' build/Testing/Temporary/LastTest.log
# The scene fixture comes first whatever its time: every CLI suite waits for it.
set(CARMBA_TEST_COSTS
  cli_scenes_fixture 1000
  BaMonteCarlo 53 CalibE2E 48 StudySlurmCluster.ShardsFailuresAndRequeue 34 StudyCliTest 32
  MarkerRecall 31 FlexCli 28 SimulatedSceneDetection 27 OutContract 23 CtFiducialsCli 21
  DetectionRecall 20 SolveCli 19 DocsOwnData 19 SaturatedMarker 18 PoseCli 17 MarkerBlobs 16
  EdgeAccuracy 15 InputsNotOutputs 14 OneGroupUnderstated/VarianceComponentsMonteCarlo 14
  JointCli 14 StudyRunnerTest 10 SceneAccuracy 10 SimulateCli 10 MarkerDetection 10
  CommandLine 10 ShadowCentre 9 StudyReportBrowserTest 8 DicomCli 8 StudySlurmTest 7
  SkullBeads 7 CameraModelUncertainty 7 OutputPaths 6 TrackCli 6 PoseSolver 6 SceneMonteCarlo 5
  Triangulation 5 python.test_calibrate 5 JointBadInput 5 JointTwoStep 5 AbsurdInput 5 RealCt 5
  DrrExportE2e 4 python.test_solve_joint 4 SkipAndSteps 4 MarkerViews 4 CrossCheck 4
  AbsurdValue 3 BadInput 3 XrayRender 3 InputGuards 3 FlexMonteCarlo 3 GridDetectorTest 3)
# Global, for the tests of other directories (tests/python).
set_property(GLOBAL PROPERTY CARMBA_TEST_COSTS "${CARMBA_TEST_COSTS}")

# Sets the COST of the test `name`, added with add_test(), if the list above has it.
function(carmba_set_test_cost name)
  get_property(costs GLOBAL PROPERTY CARMBA_TEST_COSTS)
  list(FIND costs "${name}" i)
  if(i GREATER -1)
    math(EXPR i "${i} + 1")
    list(GET costs ${i} cost)
    set_tests_properties(${name} PROPERTIES COST ${cost})
  endif()
endfunction()
