% MAAST for ARAIM 2's usr_vhpl_araim on the user-epochs written by tools/maast_map_rows.py
% (see there): LPV-200 (main_maast_araim.m's vertical settings: PHMI 9.8e-8 / 2e-9, P_THRES
% 6e-8, P_FA 3.9e-6 / 9e-7, FC_THRES 0.01, PL_TOL 1e-2, opt = 1 with sigma_acc limits 3 / 3 /
% 1.86 m and targets 35 / 40 / 15 m, fast = 1), and the map's choices: no FDE (fde_flag 0),
% no exposure (t_exp 0), N_es 1, max_pmd_flag 0. Writes /tmp/maast_rows/maast_vhpl.txt.
pkg load statistics
addpath(fullfile(fileparts(mfilename("fullpath")), "maast_shim"));
maast_prn_ranges;  % the globals usr_vhpl_araim reads (maast_shim/)
d = load('/tmp/maast_rows/los.txt');
pj = jsondecode(fileread('/tmp/maast_rows/params.json'));
prm.phmi_vert = 9.8e-8; prm.phmi_hor = 2e-9; prm.p_thres = 6e-8; prm.p_exc_thres = 1;
prm.pfa_vert = 3.9e-6; prm.pfa_hor = 9e-7; prm.p_emt = 1e-5; prm.pl_tol = 1e-2;
prm.fc_thres = 0.01; prm.N_es_int = 1; prm.N_es_cont = 1; prm.t_exp = 0;
prm.sig_acc_max_vert = 1.86; prm.sig_acc_max_hor1 = 3; prm.sig_acc_max_hor2 = 3;
prm.vpl_target = 35; prm.hpl_target = 40; prm.emt_target = 15; prm.sig_acc_target = 1.87;
prm.hpl_variant = 0; prm.max_pmd_flag = 0; prm.opt = 1; prm.fast = 1;
prm.fde_flag = 0; prm.fde_wf_flag = 0; prm.pl0_fde = 0;
isd.rconst_gps = pj.p_const_gps; isd.rconst_gal = pj.p_const_gal; isd.rconst_glo = 1e-4;
isd.rconst_bdu = 1e-4; isd.mfd_const_gps = 1; isd.mfd_const_gal = 1; isd.mfd_const_glo = 1;
isd.mfd_const_bdu = 1;
usr = d(:, 1); n_usr = max(usr);
vh = usr_vhpl_araim([d(:, 2:4) ones(size(d, 1), 1)], usr, d(:, 5), d(:, 9), d(:, 6), ...
                    d(:, 7), zeros(size(d, 1), 1), d(:, 8), ones(size(d, 1), 1), prm, isd, ...
                    repmat(MOPS_NOT_MONITORED, n_usr, 4));
[~, first] = unique(usr, 'first');
out = [d(first, 10:12) vh];
dlmwrite('/tmp/maast_rows/maast_vhpl.txt', out, 'delimiter', ' ', 'precision', 10);
printf('%d user-epochs\n', n_usr);
