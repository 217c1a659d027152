% (not a MAAST stand-in: shared by this project's drivers) The globals MAAST's usr_vhpl_araim
% reads (MAAST core's init_mops defines them, absent from maast_for_araim_2): GPS PRNs
% 1..100, Galileo 101..200 (the drivers number their satellites so), GLONASS and BeiDou unused.
global MOPS_NOT_MONITORED MOPS_MIN_GPSPRN MOPS_MAX_GPSPRN MOPS_MIN_GLOPRN MOPS_MAX_GLOPRN ...
       MOPS_MIN_GALPRN MOPS_MAX_GALPRN MOPS_MIN_BDUPRN MOPS_MAX_BDUPRN
MOPS_NOT_MONITORED = Inf; MOPS_MIN_GPSPRN = 1; MOPS_MAX_GPSPRN = 100;
MOPS_MIN_GALPRN = 101; MOPS_MAX_GALPRN = 200; MOPS_MIN_GLOPRN = 201; MOPS_MAX_GLOPRN = 236;
MOPS_MIN_BDUPRN = 301; MOPS_MAX_BDUPRN = 336;
