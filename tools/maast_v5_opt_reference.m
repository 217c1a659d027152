% Reference outputs of MAAST for ARAIM 2's position optimisation (prm.opt = 1: Blanch, Walter,
% Enge, Kropp 2015, compute_adjusted_position_1D) for tests/data/maast_v5_opt_reference.json:
% on subsets of the ADD v3.0 Appendix D geometry, mhss_raim_baseline_v5 with opt_flag 0 and 1
% (the baseline and the adjusted estimator) and usr_vhpl_araim (MAAST's trigger and keep rule,
% LPV-200 targets, no FDE, no exposure). Run with GNU Octave from a checkout of that repository:
%   octave-cli --eval "addpath('/path/to/maast_for_araim_2'); run('tools/maast_v5_opt_reference.m')"
% (MAAST's code is not part of this project; this driver only calls it.)
pkg load statistics
addpath(fullfile(fileparts(mfilename("fullpath")), "maast_shim"));
maast_prn_ranges;  % the globals usr_vhpl_araim reads (maast_shim/)
prn = [1 2 3 4 5 101 102 103 104 105]';
add_example_inputs;  % G, cint, cacc (maast_shim/)
prm.phmi_vert = 9.8e-8; prm.phmi_hor = 2e-9; prm.p_thres = 8e-8; prm.p_exc_thres = 1;
prm.pfa_vert = 3.9e-6; prm.pfa_hor = 9e-8; prm.p_emt = 1e-5; prm.pl_tol = 1e-4;
prm.N_es_int = 1; prm.N_es_cont = 1; prm.hpl_variant = 0; prm.max_pmd_flag = 0;
prm.fast = 0; prm.fc_thres = 0.01; prm.t_exp = 0; prm.opt = 1;
prm.fde_flag = 0; prm.fde_wf_flag = 0; prm.pl0_fde = 0;
prm.sig_acc_max_vert = 1.86; prm.sig_acc_max_hor1 = 3; prm.sig_acc_max_hor2 = 3;
prm.vpl_target = 35; prm.hpl_target = 40; prm.emt_target = 15; prm.sig_acc_target = 1.87;
isd.rconst_gps = 1e-4; isd.rconst_gal = 1e-4; isd.rconst_glo = 1e-4; isd.rconst_bdu = 1e-4;
isd.mfd_const_gps = 1; isd.mfd_const_gal = 1; isd.mfd_const_glo = 1; isd.mfd_const_bdu = 1;
% {0-based rows dropped, p_sat}
cases = {{[], 1e-5}, {[], 1e-4}, {[0], 1e-4}, {[5], 1e-5}, {[5], 1e-4}, {[1 6], 1e-5}, ...
         {[3 8], 1e-5}, {[2], 1e-5}};
printf('[\n');
for k = 1:numel(cases)
  drop = cases{k}{1}; p_sat = cases{k}{2};
  keep = true(10, 1); keep(drop + 1) = false; n = sum(keep);
  Gk = G(keep, :);
  [v0, h0, s0, e0] = mhss_raim_baseline_v5(Gk, cint(keep), cacc(keep), 0.5 * ones(n, 1), ...
      zeros(n, 1), p_sat, 1e-4, 0, 0, 0, prm, 1);
  [v1, h1, s1, e1] = mhss_raim_baseline_v5(Gk, cint(keep), cacc(keep), 0.5 * ones(n, 1), ...
      zeros(n, 1), p_sat, 1e-4, 0, 0, 1, prm, 1);
  vh = usr_vhpl_araim([Gk(:, 1:3) ones(n, 1)], ones(n, 1), cint(keep), prn(keep), ...
      cacc(keep), 0.5 * ones(n, 1), zeros(n, 1), p_sat * ones(n, 1), ones(n, 1), prm, isd, ...
      repmat(MOPS_NOT_MONITORED, 1, 4));  % (its nargin < 10 test never holds: pass the start)
  sep = ','; if k == numel(cases), sep = ''; end
  printf(['  {"drop": [%s], "p_sat": %.1e, ' ...
          '"baseline": {"vpl_m": %.6f, "hpl_m": %.6f, "sigma_acc_m": %.6f, "emt_m": %.6f}, ' ...
          '"adjusted": {"vpl_m": %.6f, "hpl_m": %.6f, "sigma_acc_m": %.6f, "emt_m": %.6f}, ' ...
          '"maast": {"vpl_m": %.6f, "hpl_m": %.6f, "sigma_acc_m": %.6f, "emt_m": %.6f}}%s\n'], ...
         strjoin(arrayfun(@num2str, drop, 'UniformOutput', false), ', '), p_sat, ...
         v0, h0, s0, e0, v1, h1, s1, e1, vh(1), vh(4), vh(3), vh(2), sep);
end
printf(']\n');
