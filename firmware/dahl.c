#include "dahl.h"

#include <math.h>

double dahl_flow(double H, double dx, double s, double sigma, double Ha, double alpha)
{
    double y0 = 1.0 - s * H / Ha;
    if (y0 < 0.0)
        y0 = 0.0;
    else if (y0 > 2.0)
        y0 = 2.0;
    double xi = s * dx;
    double y;
    if (alpha == 1.0) {
        y = y0 * exp(-sigma * xi / Ha);
    } else {
        double e = 1.0 - alpha;
        if (y0 == 0.0) {
            if (e < 0.0) {
                y = 0.0;
            } else {
                double z = -e * sigma * xi / Ha;
                y = z > 0.0 ? pow(z, 1.0 / e) : 0.0;
            }
        } else {
            double w = e * sigma * xi / (Ha * pow(y0, e));
            if (w >= 1.0)
                y = e > 0.0 ? 0.0 : 2.0;
            else
                y = y0 * exp(log1p(-w) / e);
        }
    }
    if (y > 2.0)
        y = 2.0;
    return s * Ha * (1.0 - y);
}
