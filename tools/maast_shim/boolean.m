function y = boolean(x)
% MATLAB's boolean (logical), which GNU Octave 7 lacks; MAAST's PL solvers call it
y = logical(x);
end
