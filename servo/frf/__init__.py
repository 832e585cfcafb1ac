"""``servo frf``: a frequency response from a recording (H1 over Welch segments, or the
reference as instrument in closed loop), with coherence and random-error bounds."""
