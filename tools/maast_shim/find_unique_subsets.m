function [subsets_unique, pfault_inst_unique, pfault_exp_unique, idx_a] = find_unique_subsets(subsets, pfault_inst, pfault_exp)
% Stand-in for MAAST's function of this name under GNU Octave 7, whose unique(..., 'rows',
% 'stable') has no third output: the distinct rows in order of first appearance, with the
% probabilities of equal rows summed (the same result, written for this project).
n = size(subsets, 1);
group = zeros(n, 1);
idx_a = [];
for i = 1:n
  for j = 1:numel(idx_a)
    if isequal(subsets(i, :), subsets(idx_a(j), :))
      group(i) = j;
      break;
    end
  end
  if group(i) == 0
    idx_a(end + 1) = i;
    group(i) = numel(idx_a);
  end
end
idx_a = idx_a(:);
subsets_unique = subsets(idx_a, :);
pfault_inst_unique = accumarray(group, pfault_inst(:));
pfault_exp_unique = accumarray(group, pfault_exp(:));
end
