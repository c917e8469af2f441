//! Numerical methods, each once for the whole tool: linear least squares, the statistics of
//! model errors, smoothed differentiation and the weak form.
pub mod differentiation;
pub mod least_squares;
pub mod quantisation;
pub mod statistics;
pub mod weak_form;
