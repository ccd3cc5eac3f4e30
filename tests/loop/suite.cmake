# Online loop-closure detection (core LoopDetector) on simulated loops and on hku-loop1.
segmatch_test_suite(test_loop loop segmatch_core segmatch_sim segmatch_io)
