//! Gauss–Legendre quadrature rules, shared by the integration cells of
//! the octree (the modal solids) and of the quadtree (thin shells).

use crate::math::Real;

/// Most Gauss points per axis of a cell.
pub const MAX_ORDER: usize = 5;

/// Gauss–Legendre abscissae and weights on [-1, 1] for 1 to 5 points
/// (Abramowitz & Stegun, Table 25.4); an order past 5 gets the 5-point
/// rule (callers check the order against [`MAX_ORDER`]).
pub fn gauss_legendre(order: usize) -> (&'static [Real], &'static [Real]) {
    const X1: [Real; 1] = [0.0];
    const W1: [Real; 1] = [2.0];
    const X2: [Real; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];
    const W2: [Real; 2] = [1.0, 1.0];
    const X3: [Real; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
    const W3: [Real; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    const X4: [Real; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const W4: [Real; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    const X5: [Real; 5] = [
        -0.906_179_845_938_664,
        -0.538_469_310_105_683,
        0.0,
        0.538_469_310_105_683,
        0.906_179_845_938_664,
    ];
    const W5: [Real; 5] = [
        0.236_926_885_056_189_1,
        0.478_628_670_499_366_5,
        0.568_888_888_888_888_9,
        0.478_628_670_499_366_5,
        0.236_926_885_056_189_1,
    ];
    match order {
        1 => (&X1, &W1),
        2 => (&X2, &W2),
        3 => (&X3, &W3),
        4 => (&X4, &W4),
        _ => (&X5, &W5),
    }
}
