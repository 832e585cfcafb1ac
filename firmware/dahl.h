/* The Dahl hysteresis flow of kernels/dahl.py, same operations in the same order. */
#ifndef SERVO_FW_DAHL_H
#define SERVO_FW_DAHL_H

/* Exact integral of the Dahl model from force H (A) over displacement dx (m) in direction
 * s (+1/-1); sigma stiffness (A/m), Ha asymptote (A), alpha shape.  Returns the force (A). */
double dahl_flow(double H, double dx, double s, double sigma, double Ha, double alpha);

#endif
