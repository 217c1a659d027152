% Reference outputs of MAAST for ARAIM 2 (stanford-gps-lab/maast_for_araim_2, the ADD v4.2
% algorithm, mhss_raim_baseline_v5) on the ADD v3.0 Appendix D geometry, for
% tests/data/maast_v5_reference.json. Run with GNU Octave from a checkout of that repository:
%   octave-cli --eval "addpath('/path/to/maast_for_araim_2'); run('tools/maast_v5_reference.m')"
% (tools/maast_shim/find_unique_subsets.m stands in for the one function Octave 7 cannot run.)
% (MAAST's code is not part of this project; this driver only calls it.)
pkg load statistics
addpath(fullfile(fileparts(mfilename("fullpath")), "maast_shim"));
add_example_inputs;  % G, cint, cacc (maast_shim/)
prm.phmi_vert = 9.8e-8; prm.phmi_hor = 2e-9; prm.p_thres = 8e-8; prm.p_exc_thres = 1;
prm.pfa_vert = 3.9e-6; prm.pfa_hor = 9e-8; prm.p_emt = 1e-5; prm.pl_tol = 1e-4;
prm.N_es_int = 1; prm.N_es_cont = 1; prm.vpl_target = 35; prm.hpl_target = 40;
prm.hpl_variant = 0; prm.max_pmd_flag = 0; prm.fast = 0;
prm.sig_acc_max_vert = 1.86; prm.sig_acc_max_hor1 = 3; prm.sig_acc_max_hor2 = 3;
cases = {[1e-5 0.01 1], [1e-4 0.01 1], [1e-5 0 1], [1e-4 0 1], [1e-5 0.01 25]};
printf('[\n');
for k = 1:numel(cases)
  p_sat = cases{k}(1); prm.fc_thres = cases{k}(2);
  prm.N_es_int = cases{k}(3); prm.N_es_cont = cases{k}(3);
  [vpl, hpl, sig_acc, emt, subsets, pfi, pfe, pnm] = mhss_raim_baseline_v5(G, cint, cacc, ...
      0.5 * ones(10, 1), zeros(10, 1), p_sat, 1e-4, 0, 0, 0, prm, 1);
  [u, ~, ~] = find_unique_subsets(subsets, pfi, pfe);
  sep = ','; if k == numel(cases), sep = ''; end
  printf(['  {"p_sat": %.1e, "fc_thres": %g, "n_es": %g, "vpl_m": %.6f, "hpl_m": %.6f, ' ...
          '"emt_m": %.6f, ' ...
          '"sigma_acc_m": %.6f, "p_not_monitored": %.6e, "n_modes": %d}%s\n'], p_sat, ...
         prm.fc_thres, prm.N_es_int, vpl, hpl, emt, sig_acc, pnm, size(u, 1) - 1, sep);
end
printf(']\n');
