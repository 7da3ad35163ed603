"""Prototype of decision 0014's "a third measurement" section: the output
smoother fed with scan-to-scan matching (laser odometry) as well as the
wheel odometry, its three noises told apart by the three-cornered hat.

Analysis only; squall does not run it and CI does not need it
(python3 with numpy and scipy). Usage:

  squall sim --world campus --seed 1 --odometry poor --out cp
  squall slam --log cp/sim.clf --seed 1 --out cp-raw \
      --set matcher.params.smoother=none --set backend.params.enabled=false
  python3 smoother_prototype.py [--floor] cp/sim.clf cp-raw/trajectory.tum out.tum [cp/ground_truth.tum]
  squall eval --trajectory out.tum --relations cp/sim.relations

It writes up to three trajectories: OUT with the three-way smoother (robust hat;
with --floor, no noise below its estimate's standard error),
OUT.current.tum (a re-implementation of today's two-way smoother),
and, given ground truth, OUT.true.tum (three-way, true noises) and prints
the noises per processed step (along, across, heading); given ground
truth, also each estimate's true error per step.
"""
import math
import numpy as np
def load_tum(p):
    d={}
    for l in open(p):
        if l.startswith('#') or not l.strip(): continue
        f=l.split(); t=float(f[0]); x,y=float(f[1]),float(f[2])
        qz,qw=float(f[6]),float(f[7]); th=2*math.atan2(qz,qw)
        d[round(t,3)]=(x,y,th)
    return d
def load_odo(clf):
    d={}
    for l in open(clf):
        f=l.split()
        if f and f[0]=='FLASER':
            n=int(f[1]); x,y,th=map(float,f[2+n:5+n]); t=float(f[-1]) if False else None
            # timestamp: after odom pose: ox oy oth ipc_timestamp host logger_timestamp
            rest=f[2+n:]
            t=float(rest[6])
            d[round(t,3)]=(float(rest[3]),float(rest[4]),float(rest[5]))
    return d
def rel(a,b):
    dx,dy=b[0]-a[0],b[1]-a[1]; c,s=math.cos(a[2]),math.sin(a[2])
    return np.array([c*dx+s*dy,-s*dx+c*dy,math.atan2(math.sin(b[2]-a[2]),math.cos(b[2]-a[2]))])
def wrap(a): return math.atan2(math.sin(a), math.cos(a))
def compose(a,b):
    c,s=math.cos(a[2]),math.sin(a[2])
    return (a[0]+c*b[0]-s*b[1], a[1]+s*b[0]+c*b[1], wrap(a[2]+b[2]))

def gate_stamps(odo, ts, lin=1.0, ang=0.5):
    out=[ts[0]]; L=A=0.0
    for a,b in zip(ts, ts[1:]):
        d=rel(odo[a],odo[b]); L+=math.hypot(d[0],d[1]); A+=abs(d[2])
        if L>=lin or A>=ang: out.append(b); L=A=0.0
    return out

def vec(p): return np.array([p[0],p[1],wrap(p[2])])
def relp(a,b): return tuple(rel(a,b))
def adjoint(p):
    c,s=math.cos(p[2]),math.sin(p[2])
    return np.array([[c,-s,p[1]],[s,c,-p[0]],[0,0,1.0]])

def fit_systematic(U,E):
    N=U.T@U; C=E.T@U
    N=N+np.eye(3)*np.trace(N)*1e-9
    return C@np.linalg.inv(N)

def vfit(res, maxspan=20, lo=1):
    n=len(res); r=res-res.mean(0)
    cum=np.vstack([np.zeros(3),np.cumsum(r,0)])
    ms=np.arange(lo,maxspan+1); V=np.array([((cum[m:]-cum[:-m])**2).mean(0) for m in ms])
    out=[]
    for c in range(3):
        A=np.vstack([np.ones(len(ms)),ms]).T
        (ic,sl),*_=np.linalg.lstsq(A,V[:,c],rcond=None)
        out.append((max(ic/2,1e-10),max(sl,1e-10)))
    return np.array([o[0] for o in out]), np.array([o[1] for o in out]), V

def solve(lin_steps, res, Rinv, Qinv_list):
    # Rinv: 3x3 prior info; Qinv_list: per step 3x3 info
    n=len(lin_steps)+1
    H=np.zeros((3*n,3*n)); g=np.zeros(3*n)
    for k in range(n): H[3*k:3*k+3,3*k:3*k+3]+=Rinv
    for k,(a,e) in enumerate(zip(lin_steps,res)):
        back=np.linalg.inv(adjoint(a)); Qi=Qinv_list[k]
        # r = e + d_{k+1} - back d_k ; J_{k+1}=I, J_k=-back
        i,j=3*k,3*k+3
        H[j:j+3,j:j+3]+=Qi; H[i:i+3,i:i+3]+=back.T@Qi@back
        H[i:i+3,j:j+3]+=-back.T@Qi; H[j:j+3,i:i+3]+=-Qi@back
        g[j:j+3]+=Qi@e; g[i:i+3]+=-back.T@Qi@e
    import scipy.sparse, scipy.sparse.linalg
    d=scipy.sparse.linalg.spsolve(scipy.sparse.csc_matrix(H),-g)
    return d.reshape(n,3)

def run(clf, rawp, variant, outp):
    odo=load_odo(clf); raw=load_tum(rawp); ts=sorted(raw)
    P=gate_stamps(odo,ts)
    lin=[raw[t] for t in P]; od=[odo[t] for t in P]
    ls=[relp(lin[k],lin[k+1]) for k in range(len(P)-1)]
    us=[relp(od[k],od[k+1]) for k in range(len(P)-1)]
    E=np.array([vec(relp(u,a)) for a,u in zip(ls,us)])  # a relative to u: u^-1 a
    U=np.array([vec(u) for u in us])
    S=fit_systematic(U,E)
    res=E-(U@S.T)
    R,Q,V=vfit(res)
    Rinv,Qinv_list=variant(R,Q,U,res,V)
    d=solve(ls,res,Rinv,Qinv_list)
    sm=[compose(lin[k],tuple(d[k])) for k in range(len(P))]
    # fill
    idx=0; out=[]
    for t in ts:
        while idx+1<len(P) and P[idx+1]<=t: idx+=1
        off=relp(odo[P[idx]],odo[t]); p=compose(sm[idx],off); out.append((t,p))
    with open(outp,'w') as f:
        for t,p in out:
            f.write(f"{t:.6f} {p[0]:.6f} {p[1]:.6f} 0 0 0 {math.sin(p[2]/2):.9f} {math.cos(p[2]/2):.9f}\n")
    return R,Q,S

def rust_variant(R,Q,U,res,V):
    return np.diag(1/R), [np.diag(1/Q)]*len(U)

def oracle(gtp, clf, rawp):
    gt=load_tum(gtp); odo=load_odo(clf); raw=load_tum(rawp); ts=sorted(raw)
    P=gate_stamps(odo,ts)
    g=[gt[t] for t in P]; o=[odo[t] for t in P]; l=[raw[t] for t in P]
    gs=[relp(g[k],g[k+1]) for k in range(len(P)-1)]
    os_=[relp(o[k],o[k+1]) for k in range(len(P)-1)]
    ls=[relp(l[k],l[k+1]) for k in range(len(P)-1)]
    U=np.array([vec(u) for u in os_])
    Eo=np.array([vec(relp(gg,u)) for gg,u in zip(gs,os_)])   # odometry step error
    So=fit_systematic(U,Eo); Ro=Eo-U@So.T
    El=np.array([vec(relp(gg,a)) for gg,a in zip(gs,ls)])    # lineage step error
    return Eo,Ro,El,So

def load_scans(clf, maxr=None):
    d={}; amin=-math.pi/2; inc=None; rmax=None
    for l in open(clf):
        f=l.split()
        if not f: continue
        if f[0]=='PARAM' and f[1]=='laser_front_laser_angle_min': amin=float(f[2])
        if f[0]=='PARAM' and f[1]=='laser_front_laser_angle_increment': inc=float(f[2])
        if f[0]=='PARAM' and f[1]=='robot_front_laser_max': rmax=float(f[2])
        if f[0]=='FLASER':
            n=int(f[1]); r=np.array(list(map(float,f[2:2+n]))); rest=f[2+n:]; t=round(float(rest[6]),3)
            a=(amin+np.arange(n)*inc) if inc else (-math.pi/2+np.arange(n)*math.pi/(n-1))
            ok=(r>0.01)&(r<(rmax if rmax else 1e9)-0.01)
            if maxr: ok&=r<maxr
            d[t]=np.c_[r[ok]*np.cos(a[ok]), r[ok]*np.sin(a[ok])]
    return d

from scipy.spatial import cKDTree
def normals(pts, tree, k=5):
    _,ii=tree.query(pts,k=k)
    N=np.zeros_like(pts); ok=np.zeros(len(pts),bool)
    for j,idx in enumerate(ii):
        q=pts[idx]; q=q-q.mean(0); C=q.T@q
        w,v=np.linalg.eigh(C)
        if w[1]>1e-12 and w[0]/w[1]<0.05: N[j]=v[:,0]; ok[j]=True
    return N,ok
def icp_pl(src,dst,guess,iters=25,reject=0.5):
    x,y,th=guess; tree=cKDTree(dst); N,okn=normals(dst,tree)
    for it in range(iters):
        c,s=math.cos(th),math.sin(th)
        p=src@np.array([[c,s],[-s,c]])+[x,y]
        dd,ii=tree.query(p)
        thr=max(reject*(0.5**(it//4)),0.08)
        m=(dd<thr)&okn[ii]
        if m.sum()<10: return None
        n=N[ii[m]]; q=dst[ii[m]]; pp=p[m]
        # r = n.(pp - q); J wrt (x,y,th): [nx, ny, n.(perp(pp - t))]
        rel_=pp-[x,y]; perp=np.c_[-rel_[:,1],rel_[:,0]]
        J=np.c_[n[:,0],n[:,1],(n*perp).sum(1)]; r=(n*(pp-q)).sum(1)
        H=J.T@J+np.eye(3)*1e-9; dlt=-np.linalg.solve(H,J.T@r)
        x+=dlt[0]; y+=dlt[1]; th+=dlt[2]
    return (x,y,th)

ROBUST_FLOOR=False
def run3(clf, rawp, outp, mode='hat', gtp=None, maxr=None):
    odo=load_odo(clf); raw=load_tum(rawp); ts=sorted(raw); sc=load_scans(clf,maxr)
    P=gate_stamps(odo,ts)
    lin=[raw[t] for t in P]; od=[odo[t] for t in P]
    ls=[relp(lin[k],lin[k+1]) for k in range(len(P)-1)]
    us=[relp(od[k],od[k+1]) for k in range(len(P)-1)]
    ss=[icp_pl(sc[P[k+1]],sc[P[k]],us[k]) for k in range(len(P)-1)]
    U=np.array([vec(u) for u in us])
    E=np.array([vec(relp(u,a)) for a,u in zip(ls,us)])
    S=fit_systematic(U,E); Eo=E-(U@S.T)           # lineage vs calibrated odometry
    # s2s residual: s^-1 a, and odometry-vs-s  (o - s) in comparable terms
    Es=np.array([vec(relp(s,a)) if s is not None else [np.nan]*3 for a,s in zip(ls,ss)])
    ok=~np.isnan(Es).any(1)
    d=np.abs(Eo-Es); med=np.nanmedian(d,0)*1.4826
    ok&=(d<6*med+1e-9).all(1)
    # hat on steps where all three exist: a=o-l = -Eo ; b = o - s = Es - Eo (approx, small)
    def rv(x): return (np.median(np.abs(x-np.median(x,0)),0)*1.4826)**2
    Vol=rv(Eo[ok]); Vls=rv(Es[ok]); Vos=rv((Es-Eo)[ok])
    vo=np.maximum((Vol+Vos-Vls)/2,1e-8); vl=np.maximum((Vol+Vls-Vos)/2,1e-8); vs=np.maximum((Vos+Vls-Vol)/2,1e-8)
    if ROBUST_FLOOR:
        # No noise below the estimate's own standard error (a MAD variance
        # from n samples: about 1.65 * V * sqrt(2/n)).
        n=ok.sum(); se=lambda V: V*math.sqrt(2/n)*1.65
        fl=np.sqrt(se(Vol)**2+se(Vos)**2+se(Vls)**2)/2
        vo=np.maximum(vo,fl); vs=np.maximum(vs,fl); vl=np.maximum(vl,fl)
    if mode=='true':
        gt=load_tum(gtp); g=[gt[t] for t in P]; gs=[relp(g[k],g[k+1]) for k in range(len(P)-1)]
        To=np.array([vec(relp(gg,u)) for gg,u in zip(gs,us)]); To=To-U@fit_systematic(U,To).T
        Ts=np.array([vec(relp(gg,s)) for gg,s,o_ in zip(gs,ss,ok) if o_ ])
        vo=To.var(0); vs=Ts.var(0); vl=np.array([vec(relp(gg,a)) for gg,a in zip(gs,ls)]).var(0)
    R=vl
    Qi=[]; res=[]
    Ioi=np.diag(1/np.maximum(vo,1e-10)); Isi=np.diag(1/np.maximum(vs,1e-10))
    for k in range(len(ls)):
        if ok[k]:
            I=Ioi+Isi; Ci=np.linalg.inv(I); e=Ci@(Ioi@Eo[k]+Isi@Es[k])
        else: I=Ioi; e=Eo[k]
        Qi.append(I); res.append(e)
    dd=solve(ls,np.array(res),np.diag(1/R),Qi)
    sm=[compose(lin[k],tuple(dd[k])) for k in range(len(P))]
    idx=0
    with open(outp,'w') as f:
        for t in ts:
            while idx+1<len(P) and P[idx+1]<=t: idx+=1
            p=compose(sm[idx],relp(od[idx],odo[t]))
            f.write(f"{t:.6f} {p[0]:.6f} {p[1]:.6f} 0 0 0 {math.sin(p[2]/2):.9f} {math.cos(p[2]/2):.9f}\n")
    return np.sqrt(vo),np.sqrt(vs),np.sqrt(vl),ok.mean()


if __name__ == "__main__":
    import sys
    args = [a for a in sys.argv[1:] if a != '--floor']
    ROBUST_FLOOR = '--floor' in sys.argv
    clf, raw, out = args[:3]
    truth = args[3] if len(args) > 3 else None
    so, ss, sl, kept = run3(clf, raw, out, 'hat')
    print("hat: odometry", np.round(so, 4), "scan-to-scan", np.round(ss, 4), "lineage", np.round(sl, 4),
          "steps matched %.2f" % kept)
    fitted_r, fitted_q, _ = run(clf, raw, rust_variant, out + '.current.tum')
    print("today's fit: lineage (R)", np.round(np.sqrt(fitted_r), 4), "odometry (Q)", np.round(np.sqrt(fitted_q), 4))
    if truth:
        so, ss, sl, _ = run3(clf, raw, out + '.true.tum', 'true', truth)
        print("true: odometry", np.round(so, 4), "scan-to-scan", np.round(ss, 4), "lineage", np.round(sl, 4))
        # The unsmoothed lineage's and the calibrated odometry's error per
        # processed step, and the lineage's lag-1 correlation (white pose
        # noise: -0.5; a random walk: 0).
        _, odometry, lineage, _ = oracle(truth, clf, raw)
        lag1 = [np.corrcoef(lineage[1:, c], lineage[:-1, c])[0, 1] for c in range(3)]
        print("per step, all steps: lineage", np.round(lineage.std(0), 4), "odometry", np.round(odometry.std(0), 4),
              "lineage lag-1", np.round(lag1, 2))
