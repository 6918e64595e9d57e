"""Dense modal reference for the dynamics tests (serial)."""
import numpy as np
import scipy.linalg

from fabricfem.dynamics import consistent_mass


def first_mode(model):
    """Dense first eigenpair (omega1, mode as a Vec) of K phi = omega^2 M phi on the free dofs (serial)."""
    K = model.create_matrix()
    model.jacobian(model.w.vector, K)
    M = consistent_mass(model, model.bcs, diagonal=0.0)
    Kd, Md = K.convert("dense").getDenseArray(), M.convert("dense").getDenseArray()
    bc = np.concatenate([bc.dof_indices()[0] for bc in model.bcs])
    free = np.setdiff1d(np.arange(Kd.shape[0]), bc)
    w2, phi = scipy.linalg.eigh(Kd[np.ix_(free, free)], Md[np.ix_(free, free)], subset_by_index=[0, 0])
    mode = model.create_vector()
    mode.set(0.0)
    mode.getArray()[free] = phi[:, 0]
    return float(np.sqrt(w2[0])), mode
