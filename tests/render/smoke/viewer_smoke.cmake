# Runs crumple-view under Xvfb and checks its screenshot. Arguments: VIEWER, CHECKER,
# XVFB_RUN (may be empty or NOTFOUND), OUT.
if(NOT XVFB_RUN OR NOT EXISTS "${XVFB_RUN}")
  find_program(XVFB_RUN xvfb-run)
endif()
if(NOT XVFB_RUN)
  message(FATAL_ERROR "viewer.smoke: xvfb-run not found; install it (apt-get install xvfb xauth, "
                      "or `bash scripts/dev.sh test`)")
endif()
# Under LeakSanitizer the Mesa driver's allocations, made in a library unloaded (dlclose) before
# the leak check, show as leaks with unresolvable stacks that no suppression can match: leak
# checking is off for the viewer process only (AddressSanitizer and UBSan stay on; the library
# code it calls is leak-checked by test_render and test_cli).
if(DEFINED ENV{ASAN_OPTIONS} AND NOT "$ENV{ASAN_OPTIONS}" STREQUAL "")
  set(ENV{ASAN_OPTIONS} "$ENV{ASAN_OPTIONS}:detect_leaks=0")
else()
  set(ENV{ASAN_OPTIONS} "detect_leaks=0")
endif()
# Runs the viewer headless with ARGN after removing SHOT, which it is to write; sets rc, out
# and err in the caller and prints the output under LABEL.
function(run_viewer label shot)
  file(REMOVE "${shot}")
  execute_process(
    COMMAND ${XVFB_RUN} -a -s "-screen 0 1024x768x24" "${VIEWER}" ${ARGN} --screenshot "${shot}" --exit
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 240)
  message(STATUS "crumple-view${label}: ${out}${err}")
  set(rc "${rc}" PARENT_SCOPE)
  set(out "${out}" PARENT_SCOPE)
  set(err "${err}" PARENT_SCOPE)
endfunction()

run_viewer("" "${OUT}" hanging-cloth --frames 160)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "viewer.smoke: crumple-view exited with '${rc}'")
endif()
if(NOT out MATCHES "method kdop")
  message(FATAL_ERROR "viewer.smoke: crumple-view did not use its default method kdop")
endif()
if(NOT EXISTS "${OUT}")
  message(FATAL_ERROR "viewer.smoke: no screenshot written to ${OUT}")
endif()
execute_process(COMMAND "${CHECKER}" "${OUT}" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "viewer.smoke: the screenshot failed the check")
endif()
# A diverging simulation (sim::DivergenceError) pauses the viewer with the message instead of
# ending it: the picture of the last good state is still taken; a scripted run exits 1.
set(DIVERGED "${OUT}.diverged.png")
run_viewer(" (diverging)" "${DIVERGED}" hanging-cloth -p gravity=1e12 --frames 5)
if(NOT rc EQUAL 1 OR NOT err MATCHES "diverged at frame 1")
  message(FATAL_ERROR "viewer.smoke: a diverging run exited with '${rc}' without the divergence message")
endif()
if(NOT EXISTS "${DIVERGED}")
  message(FATAL_ERROR "viewer.smoke: a diverging run ended before its screenshot")
endif()
# Untangling, as `crumple simulate --response-from`: the 12 x 12 hanging cloth falls through
# itself for 300 frames with the response off, then untangles; the headless run prints the
# intersecting pairs' count (as the panel shows it) and the simulated frames per second.
# With CRUMPLE_PROGRESS_SECONDS=0 the headless frames report their progress at once.
set(UNTANGLED "${OUT}.untangled.png")
set(ENV{CRUMPLE_PROGRESS_SECONDS} 0)
run_viewer(" (untangling)" "${UNTANGLED}" hanging-cloth:nx=12,ny=12 --response-from 300 --frames 340)
unset(ENV{CRUMPLE_PROGRESS_SECONDS})
if(NOT err MATCHES "crumple-view: frame [0-9]+/340, ")
  message(FATAL_ERROR "viewer.smoke: the headless frames printed no progress")
endif()
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "viewer.smoke: the untangling run exited with '${rc}'")
endif()
if(NOT out MATCHES "intersecting pairs: 0, [1-9][0-9]* at frame 300, 0 from frame 3[0-3][0-9]")
  message(FATAL_ERROR "viewer.smoke: the tangled cloth did not reach 0 intersecting pairs within 40 frames")
endif()
if(NOT out MATCHES "[0-9.]+ frames per second")
  message(FATAL_ERROR "viewer.smoke: no frames per second printed")
endif()
